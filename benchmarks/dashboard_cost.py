"""What watching a run costs it, and how late the page shows a step.

Overhead: the barrier ring of benchmarks/barrier.py (N nodes, y = 0.5·u + 1) run by
``hycosim run``, once plain and once with ``--dashboard`` and a headless chromium page open on
it plotting a port, the rounds interleaved; steps/s medians and their ratio. Beside them
(``--least-page``) the same run plain with the browser showing the least page updated as often
as the dashboard's (a line of text changed five times a second): what any page open in a
browser costs the run on this machine, whatever it shows. And (``--page-elsewhere``) with the
dashboard fed to a page on another machine: a WebSocket client takes the page's snapshots (the
page's selection, every push) and draws nothing, so that only the dashboard's work is on this
one (``hycosim dashboard EP`` with the browser on a workstation, as for a fast run on a small
machine).

Latency: a paced run (100 steps per second of wall time) with the dashboard and the page;
for every step, the time from its point at the server (all its outputs in: the server's wall
clock, in the status answer) to the first snapshot reaching the page that shows it or a later
step (points are 10 ms apart, so a step's time is the shown point's less the steps between).

What watching takes: during the paced run, the CPU of the browser's processes and of the
dashboard's, as a share of one core and per update the page received; and, for scale, the same
browser showing a page that changes one line of text as often (the least any page updated at
that rate costs the browser). When a run keeps every core busy, what they take of the machine
comes out of the run's share.

A big finished run: a run directory of ``--big`` steps (two nodes, written as the recorder
writes them) opened with ``hycosim dashboard RUN_DIR``: seconds until the page lists the nodes
(usable), and until a chosen port's plot has drawn.

    python benchmarks/dashboard_cost.py [--n 2] [--steps 20000] [--repeat 3] [--least-page] [--page-elsewhere]
                                        [--wait-strategy auto] [--paced-s 20] [--big 1000000] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
import urllib.request
from pathlib import Path

import _table
from _procs import descendants, free_port, kill_group, start

from barrier import ring_config

REPO = Path(__file__).resolve().parent.parent
CORES = len(os.sched_getaffinity(0))


def _page_up(url: str, timeout: float = 60) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(url, timeout=1):
                return
        except OSError:
            time.sleep(0.05)
    raise RuntimeError(f"no dashboard at {url}")


def _cpu_by_kind() -> dict[str, float]:
    """CPU seconds used so far by this process's descendants, by kind: ``browser`` (chromium's
    processes) and ``dashboard`` (``hycosim dashboard``); the rest (the run, Playwright's driver)
    is left out."""
    used = {"browser": 0.0, "dashboard": 0.0}
    for pid in descendants(os.getpid()):
        try:
            argv = open(f"/proc/{pid}/cmdline").read().split("\0")
            fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
        except OSError:
            continue  # gone meanwhile
        command = argv[argv.index("hycosim") + 1:argv.index("hycosim") + 2] if "hycosim" in argv else []
        # Chromium's child processes write their whole command line into argv[0].
        kind = ("browser" if os.path.basename(argv[0].split(" ", 1)[0]) == "chromium"
                else "dashboard" if command == ["dashboard"] else None)
        if kind:
            used[kind] += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return used


def _sample_cpu(seconds: float, out: dict) -> None:
    """Once the dashboard has run for six seconds (the page loaded and fed), the CPU of the
    browser and the dashboard over ``seconds`` into ``out``, with the window's wall-clock ends
    (the page's reports of its snapshots reach the harness only when it closes the page)."""
    deadline = time.monotonic() + 120
    while not _cpu_by_kind()["dashboard"] and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(6.0)  # a page's first seconds (loading, compiling, first layout) take a core's quarter
    before, began, wall0 = _cpu_by_kind(), time.monotonic(), time.time()
    time.sleep(seconds)
    after, took = _cpu_by_kind(), time.monotonic() - began
    out.update({kind: (after[kind] - before[kind]) / took for kind in after}, window=(wall0, time.time()))


def least_page(rate_hz: float) -> str:
    """The URL of a page that changes one line of text ``rate_hz`` times a second: the least a
    page updated at that rate asks of a browser."""
    line = ("<p id=n>0</p><script>let i = 0; setInterval(() => "
            f"{{ document.getElementById('n').textContent = ++i; }}, {1000 / rate_hz:.0f});</script>")
    return "data:text/html," + urllib.parse.quote(line)


def browser_floor(rate_hz: float, seconds: float = 8.0) -> float:
    """The share of one core headless chromium takes to show :func:`least_page` (its own work
    per update, whatever the page)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=shutil.which("chromium"), args=["--no-sandbox"])
        page = browser.new_page()
        page.goto(least_page(rate_hz))
        time.sleep(2.0)
        before, began = _cpu_by_kind()["browser"], time.monotonic()
        time.sleep(seconds)
        share = (_cpu_by_kind()["browser"] - before) / (time.monotonic() - began)
        browser.close()
    return share


def _watch(url: str, launched: threading.Event, until: threading.Event, seen: list | None) -> None:
    """Launch headless chromium (before the run starts: its start-up is no part of what the run
    pays), then open the page, plotting ``n0.y``, and keep it open until told. ``seen``: also
    record every snapshot the page receives, as (step, the point's wall time) and the wall time
    it arrived (the latency run only; kept in the page and read when it closes, so that the
    harness adds only a parse and an append to the page's work at each snapshot)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=shutil.which("chromium"), args=["--no-sandbox"])
        page = browser.new_page()
        if seen is not None:
            page.add_init_script("""
            window.hycosimSeen = [];
            const Real = WebSocket;
            window.WebSocket = function (...a) { const ws = new Real(...a);
              ws.addEventListener('message', (ev) => { const m = JSON.parse(ev.data);
                if (m.state === 'running' && m.point_wall) window.hycosimSeen.push([[m.step, m.point_wall], Date.now() / 1000]); });
              return ws; };""")
        page.goto("about:blank")
        launched.set()
        if url.startswith("data:"):
            page.goto(url)
        else:
            _page_up(url)
            page.goto(url + "?ports=n0.y")
        until.wait()
        if seen is not None:
            seen += [((step, point), at) for (step, point), at in page.evaluate("window.hycosimSeen")]
        browser.close()


def _feed_elsewhere(url: str, launched: threading.Event, until: threading.Event, got: list) -> None:
    """Read the dashboard's feed at ``url`` as the page does (plotting ``n0.y``) until told,
    drawing nothing; append the number of snapshots it received."""
    from websockets.exceptions import WebSocketException
    from websockets.sync.client import connect

    launched.set()
    _page_up(url)
    snapshots = 0
    with connect(url.replace("http://", "ws://") + "ws") as ws:
        ws.send(json.dumps({"select": ["n0.y"]}))
        while not until.is_set():
            try:
                message = json.loads(ws.recv(timeout=0.5))
            except TimeoutError:
                continue
            except WebSocketException:
                break  # the run, and with it the dashboard, ended
            snapshots += "state" in message
    got.append(snapshots)


def run(cfg: Path, runs: Path, dashboard: bool, seen: list | None = None, timeout: float = 300,
        page: str | None = None, elsewhere: list | None = None) -> dict:
    """``hycosim run`` the project (with the dashboard and a page on it, or, given ``elsewhere``,
    its feed read as by a page on another machine, the snapshots counted there; or plain, with
    the browser showing ``page``); its meta.json (steps/s, the wait strategy it ran with)."""
    args = [sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", str(runs), "--no-progress"]
    launched, done = threading.Event(), threading.Event()
    watcher = None
    if dashboard:
        port = free_port()
        args += ["--dashboard", "--dashboard-port", str(port)]
        page = f"http://127.0.0.1:{port}/"
    if elsewhere is not None:
        watcher = threading.Thread(target=_feed_elsewhere, args=(page, launched, done, elsewhere))
        watcher.start()
        launched.wait(60)
    elif page is not None:
        watcher = threading.Thread(target=_watch, args=(page, launched, done, seen))
        watcher.start()
        launched.wait(60)
    proc = start(args, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        kill_group(proc)
        raise
    finally:
        done.set()
        if watcher:
            watcher.join(timeout=30)
    if proc.returncode:
        raise RuntimeError(f"run failed ({proc.returncode}): {err[-800:]}")
    return json.loads(max(runs.glob("*/meta.json"), key=lambda p: p.stat().st_mtime).read_text())


def big_run(run_dir: Path, steps: int) -> Path:
    """A completed run of ``steps`` steps as the recorder leaves it (two nodes, one switch)."""
    import csv
    import math

    run_dir.mkdir(parents=True)
    with open(run_dir / "values.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "t", "mode", "a.y", "b.y", "b.u"])
        for k in range(steps + 1):
            t = k * 0.001
            w.writerow([k, repr(t), "free" if k < steps // 2 else "hold", math.sin(t), math.cos(t), math.sin(t)])
    with open(run_dir / "timing.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "t", "wait_s", "holder", "lateness_s", "arrival_s:a", "arrival_s:b"])
        for k in range(steps + 1):
            w.writerow([k, repr(k * 0.001), "0.000300000", "ab"[k % 2], "", "0.000200000", "0.000300000"])
    (run_dir / "events.jsonl").write_text(json.dumps({"step": steps // 2, "t": steps // 2 * 0.001, "event": "hold",
                                                      "from": "free", "to": "hold", "guard": "a.y > 0",
                                                      "values": {"a.y": 0.5}}) + "\n")
    (run_dir / "meta.json").write_text(json.dumps({"status": "completed", "steps": steps + 1, "steps_per_s": 3000.0}))
    return run_dir


def open_big(run_dir: Path) -> dict:
    """Seconds from opening the page until the nodes are listed, and until the plot has drawn."""
    from playwright.sync_api import sync_playwright

    port = free_port()
    board = start([sys.executable, "-m", "hycosim", "dashboard", str(run_dir), "--port", str(port)], cwd=REPO,
                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        _page_up(f"http://127.0.0.1:{port}/")
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=shutil.which("chromium"), args=["--no-sandbox"])
            page = browser.new_page()
            began = time.perf_counter()
            page.goto(f"http://127.0.0.1:{port}/?ports=a.y")
            page.wait_for_selector("tr[data-node='b']", timeout=120_000)
            usable = time.perf_counter() - began
            page.wait_for_function("window.hycosim.plots['a.y'] && window.hycosim.plots['a.y'].drawn > 100",
                                   timeout=120_000)
            drawn = time.perf_counter() - began
            points = page.evaluate("window.hycosim.plots['a.y'].drawn")
            browser.close()
    finally:
        kill_group(board)
    return {"usable_s": usable, "plot_s": drawn, "points_sent": points}


def latencies(seen: list, step_wall: float) -> list[float]:
    """For each step, the seconds from its point at the server to the first snapshot showing it or later."""
    out, shown = [], -1
    for (step, released), at in seen:
        for k in range(shown + 1, step + 1):
            out.append(at - (released - (step - k) * step_wall))
        shown = max(shown, step)
    return out


def ratio_interval(plain: list[float], board: list[float], level: float = 0.9, draws: int = 2000) -> tuple[float, float]:
    """A bootstrap interval of the ratio of the medians, resampling whole rounds (a round's two
    runs share the machine's state of the moment): how far a set of rounds can tell the ratio."""
    import random

    rng = random.Random(0)
    rounds = list(zip(plain, board))
    got = []
    for _ in range(draws):
        pick = [rng.choice(rounds) for _ in rounds]
        got.append(statistics.median(b for _, b in pick) / statistics.median(p for p, _ in pick))
    got.sort()
    return got[int((1 - level) / 2 * draws)], got[int((1 + level) / 2 * draws) - 1]


def main() -> None:
    """Measure a run's rate watched against left alone, and how late the page shows a step; print the
    figures (``--json``: one object)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2)
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--least-page", action="store_true",
                    help="also run plain with a browser showing the least page updated five times a second")
    ap.add_argument("--page-elsewhere", action="store_true",
                    help="also run with the dashboard feeding a page on another machine (a WebSocket client here)")
    ap.add_argument("--wait-strategy", choices=["auto", "block", "yield"], default="auto",
                    help="coSimulation.waitStrategy of the measured runs")
    ap.add_argument("--paced-s", type=float, default=20.0)
    ap.add_argument("--big", type=int, default=1_000_000, help="steps of the finished run opened (0: none)")
    ap.add_argument("--json", action="store_true")
    _table.add_argument(ap)
    args = ap.parse_args()
    rates: dict[str, list[float]] = {"plain": [], "dashboard": []}
    if args.least_page:
        rates["least_page"] = []
    if args.page_elsewhere:
        rates["page_elsewhere"] = []
    strategies: set[str] = set()  # as the runs recorded them
    fed: list[int] = []  # snapshots the page elsewhere received, by run
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for i in range(args.repeat):
            # Each round the other way round: a run after a run of the other kind meets a machine
            # in another state (caches, the page's browser just closed), whichever kind it is.
            for kind in (list(rates) if i % 2 == 0 else list(rates)[::-1]):
                cfg = ring_config(args.n, args.steps, tmp / f"ring-{kind}-{i}.json", args.wait_strategy)
                meta = run(cfg, tmp / f"runs-{kind}-{i}", kind in ("dashboard", "page_elsewhere"),
                           page=least_page(5.0) if kind == "least_page" else None,
                           elsewhere=fed if kind == "page_elsewhere" else None)
                rates[kind].append(float(meta["steps_per_s"]))
                strategies.add(meta["waitStrategy"])
        cfg = ring_config(args.n, int(args.paced_s / 0.01), tmp / "paced.json")
        doc = json.loads(cfg.read_text())
        doc["coSimulation"].update(stepSize=0.01, stopTime=args.paced_s, realTime=True)
        cfg.write_text(json.dumps(doc))
        seen: list = []
        taken: dict = {}
        sampler = threading.Thread(target=_sample_cpu, args=(max(1.0, args.paced_s - 8.0), taken), daemon=True)
        sampler.start()
        run(cfg, tmp / "runs-paced", True, seen)
        sampler.join(timeout=10)
        if "window" in taken:
            wall0, wall1 = taken.pop("window")
            taken["updates_per_s"] = sum(wall0 <= at <= wall1 for _, at in seen) / (wall1 - wall0)
        floor = browser_floor(taken["updates_per_s"]) if taken.get("updates_per_s") else None
        big = open_big(big_run(tmp / "big", args.big)) if args.big else None
    lat = sorted(latencies(seen, 0.01))
    plain, board = statistics.median(rates["plain"]), statistics.median(rates["dashboard"])
    low, high = ratio_interval(rates["plain"], rates["dashboard"])
    least = statistics.median(rates["least_page"]) if args.least_page else None
    elsewhere = statistics.median(rates["page_elsewhere"]) if args.page_elsewhere else None
    result = {"n": args.n, "steps": args.steps, "wait_strategy": "/".join(sorted(strategies)), "steps_per_s": rates,
              "median_plain": plain, "median_dashboard": board, "ratio": board / plain, "ratio_90": [low, high],
              **({"median_least_page": least, "least_page_ratio": least / plain,
                  "least_page_ratio_90": list(ratio_interval(rates["plain"], rates["least_page"]))}
                 if args.least_page else {}),
              **({"median_page_elsewhere": elsewhere, "page_elsewhere_ratio": elsewhere / plain,
                  "page_elsewhere_ratio_90": list(ratio_interval(rates["plain"], rates["page_elsewhere"])),
                  "page_elsewhere_snapshots": fed} if args.page_elsewhere else {}),
              "latency_ms": {"steps": len(lat), "median": 1000 * statistics.median(lat) if lat else None,
                             "p95": 1000 * lat[int(0.95 * (len(lat) - 1))] if lat else None},
              "watching": {**taken, "browser_floor": floor, "cores": CORES} if taken else None,
              "big_run": big}
    _table.write(args.table, _manual_table(args, result))
    if args.json:
        print(json.dumps(result, indent=1))
        return
    print(f"ring of {args.n}, {args.steps} steps, waitStrategy {result['wait_strategy']}, "
          f"{args.repeat} interleaved rounds (medians):")
    print(f"  plain {plain:,.0f} steps/s, with the dashboard and a page open {board:,.0f} steps/s: "
          f"ratio {board / plain:.3f} (90 % bootstrap interval over rounds {low:.3f}–{high:.3f})")
    if least is not None:
        a, b = result["least_page_ratio_90"]
        print(f"  plain with a browser showing a line of text changed 5 times a second {least:,.0f} steps/s: "
              f"ratio {least / plain:.3f} ({a:.3f}–{b:.3f}); the dashboard against it {board / least:.3f}")
    if elsewhere is not None:
        a, b = result["page_elsewhere_ratio_90"]
        print(f"  with the dashboard feeding a page on another machine {elsewhere:,.0f} steps/s: "
              f"ratio {elsewhere / plain:.3f} ({a:.3f}–{b:.3f})")
    la = result["latency_ms"]
    if lat:
        print(f"release to page, paced run of {args.paced_s:g} s ({la['steps']} steps shown): "
              f"median {la['median']:.0f} ms, 95th percentile {la['p95']:.0f} ms")
    if taken.get("updates_per_s"):
        per = 1000 / taken["updates_per_s"]
        machine = (taken["browser"] + taken["dashboard"]) / CORES
        print(f"what watching takes, paced run ({taken['updates_per_s']:.1f} updates/s): the browser "
              f"{100 * taken['browser']:.1f} % of a core ({per * taken['browser']:.1f} ms an update; a page changing "
              f"one line as often: {100 * floor:.1f} %, {per * floor:.1f} ms), the dashboard "
              f"{100 * taken['dashboard']:.1f} %; together {100 * machine:.1f} % of the machine's {CORES} cores")
    else:
        print("what watching takes: not measured (the page got no snapshot while the CPU was sampled)")
    if big:
        print(f"a finished run of {args.big:,} steps: the page usable after {big['usable_s']:.2f} s, the plot drawn "
              f"after {big['plot_s']:.2f} s ({big['points_sent']:,} points sent)")


def _manual_table(args: argparse.Namespace, r: dict) -> _table.Table:
    def against_plain(key: str, interval: str) -> str:
        low, high = r[interval]
        return f"{r[key]:.3f} ({low:.3f}–{high:.3f})"

    rows = [["the dashboard and its page here", against_plain("ratio", "ratio_90")]]
    if "least_page_ratio" in r:
        rows.append(["any page here (one line, 5/s)", against_plain("least_page_ratio", "least_page_ratio_90")])
    if "page_elsewhere_ratio" in r:
        rows.append(["the dashboard, its page on another machine",
                     against_plain("page_elsewhere_ratio", "page_elsewhere_ratio_90")])
    lat = r["latency_ms"]
    if lat["median"] is not None:
        rows.append(["a step reaches the page", f"{lat['median']:.0f} ms median, {lat['p95']:.0f} ms 95th percentile"])
    if r["big_run"]:
        big = r["big_run"]
        rows.append([f"a finished run of {args.big:,} steps", f"usable after {big['usable_s']:.2f} s, "
                                                              f"plotted after {big['plot_s']:.2f} s"])
    return _table.Table(
        f"A ring of {args.n}, {args.steps:,} steps, `waitStrategy` {r['wait_strategy']}, medians of {args.repeat} "
        "interleaved rounds; steps/s against the run plain (90 % bootstrap interval):", ["case", "figure"], rows)


if __name__ == "__main__":
    main()
