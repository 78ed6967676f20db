"""Crash recovery: runs that lose node processes or their server end as if nothing happened.

One deterministic project of four nodes (the grasp scenario's rod and robot-scene FMUs, its
reference controller and a pendulum, both Python nodes; H = 10 ms), with checkpoints every
``--every`` s, runs three times in one go:

* as it is (the reference);
* with ``--node-kills`` SIGKILLs of random node processes, spread over the run (``hycosim run``
  starts each dead node again; the server restores the last checkpoint);
* with ``--server-kills`` SIGKILLs of the server, each followed by ``hycosim run --resume``.

Each must complete with a ``values.csv`` identical, byte for byte, to the reference's, one row
per step. Then replay: the paper's scenario (rod and robot FMUs, policy, camera at 60 Hz, paced
by the wall clock) runs once as a trial, and again with its camera played back from the trial's
run directory: the two ``values.csv`` must be identical (the policy's ``infer_ms``, a wall-clock
measurement, is left out of both). Then the cost of taking checkpoints: the barrier benchmark's ring (N = 2, H = 1 ms)
with checkpoints every 1 s against the same without, interleaved rounds, medians. Recovery
times (a node's death to the restored run) come from the run's meta.json.

    python benchmarks/recovery.py [--stop 60] [--node-kills 20] [--server-kills 3] [--every 1]
                                  [--replay-stop 2.6] [--ring-steps 20000] [--repeat 3] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import _table
from _procs import free_port
from barrier import ring_config

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))

from hycosim.master import checkpoints  # noqa: E402


def project(dir_: Path, stop: float, every: float) -> Path:
    """The grasp scenario on FMUs plus a pendulum: four nodes, FMU and Python, checkpoints on."""
    from hycosim.scenario.scene_fmus import ensure_scene_fmus

    fmus = ensure_scene_fmus(REPO / "build" / "fmus")
    doc = json.loads((REPO / "hycosim" / "scenario" / "configs" / "grasp-fmu.json").read_text())
    doc["projectName"] = "recovery"
    doc["serverIP"] = f"127.0.0.1:{free_port()}"
    for node in doc["nodeLists"]:
        if node["nodeName"] in fmus:
            node["fmu"] = str(fmus[node["nodeName"]])
    doc["nodeLists"].append({"nodeName": "pendulum", "UID": 9, "model": "pendulum",
                             "parameters": {"theta0": 0.7, "damping": 0.02}, "input": [], "output": ["theta", "omega"]})
    doc["nodeNum"] = len(doc["nodeLists"])
    doc["coSimulation"].update(stopTime=stop, checkpointEvery=every, attachTimeout=30.0)
    path = dir_ / "recovery.json"
    path.write_text(json.dumps(doc, indent=1))
    return path


def pids(pattern: str) -> list[int]:
    """Processes whose command line holds ``pattern``."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            cmd = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if pattern in cmd and "recovery.py" not in cmd:
            found.append(int(entry))
    return found


def hycosim_run(cfg: Path, runs: Path, *extra: str, timeout: float = 900.0) -> subprocess.CompletedProcess:
    """``hycosim run`` of ``cfg`` into ``runs`` (with ``extra`` options), to its end."""
    return subprocess.run([sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", str(runs), "--no-progress",
                           *extra], capture_output=True, text=True, timeout=timeout, cwd=REPO)


def newest_run(runs: Path) -> Path:
    """The run directory under ``runs`` written last."""
    return max((p for p in runs.iterdir() if p.is_dir()), key=lambda p: p.stat().st_mtime)


def killer(cfg: Path, runs: Path, names: list[str], kills: int, rng: random.Random, log: list) -> None:
    """SIGKILL ``kills`` random node processes spread over the run's steps, once it has its first
    checkpoint, and none in the last fifth of the run: a node killed as the run ends dies in its
    shutdown, which ``hycosim run`` rightly reports as a failure. Each kill waits for a row of
    ``values.csv``, not for a time: timed by the reference run's wall clock, a run that went faster
    under load was past its last fifth before the first kill came (none landed, once in `make test`)."""
    cosim = json.loads(cfg.read_text())["coSimulation"]
    rows = cosim["stopTime"] / cosim["stepSize"]
    last_kill_row = 0.8 * rows
    deadline = time.monotonic() + 120
    before = set(runs.iterdir())
    while time.monotonic() < deadline and not any((p / "checkpoints").is_dir() for p in set(runs.iterdir()) - before):
        time.sleep(0.1)
    run = next(iter(set(runs.iterdir()) - before), None)
    landed = 0  # kills that found a process: each is one restore
    for i in range(kills):
        # The i-th of ``kills`` equal parts of rows 10-80 %, somewhere in its middle.
        target = rows * (0.1 + 0.7 * (i + rng.uniform(0.2, 0.8)) / kills)
        while run is not None and time.monotonic() < deadline + 60 * (i + 1) and check_rows_so_far(run / "values.csv") < target:
            if not running(run):
                return
            time.sleep(0.05)  # the file is read whole: no faster, or the reading loads the run
        name = rng.choice(names)
        killed = len(log)
        if run is None or check_rows_so_far(run / "values.csv") > last_kill_row:
            continue
        for pid in pids(f"hycosim node {name} {cfg}"):
            try:
                os.kill(pid, signal.SIGKILL)
                log.append((time.time(), name, pid))
            except ProcessLookupError:
                pass
        if len(log) == killed:
            continue  # the run is over (a short one): nothing to wait for
        landed += 1
        # One kill, one restore: the next waits until the run is back (meta.json lists it), or over.
        while run is not None and time.monotonic() < deadline + 60 * (i + 1):
            try:
                meta = json.loads((run / "meta.json").read_text())
                if len(meta.get("recoveries", [])) >= landed or meta.get("status") != "running":
                    break
            except (OSError, ValueError):
                pass
            time.sleep(0.05)


def running(run: Path) -> bool:
    """Whether the run's meta.json still says so (True while it cannot be read)."""
    try:
        return json.loads((run / "meta.json").read_text()).get("status") == "running"
    except (OSError, ValueError):
        return True


def check_rows_so_far(values: Path) -> int:
    """Rows recorded so far (a running run's file)."""
    try:
        return max(len(values.read_bytes().splitlines()) - 1, 0)
    except OSError:
        return 0


def check_rows(values: Path) -> int:
    """The number of rows; AssertionError unless the steps run 0, 1, 2… without a gap or repeat."""
    lines = values.read_text().splitlines()[1:]
    steps = [int(line.split(",", 1)[0]) for line in lines]
    assert steps == list(range(len(steps))), "a step lost or recorded twice"
    return len(steps)


def node_kills(cfg: Path, runs: Path, names: list[str], kills: int, seed: int) -> tuple[Path, list, dict]:
    """A run whose node processes are killed ``kills`` times: its run directory, the kills and its
    meta.json."""
    log: list = []
    t = threading.Thread(target=killer, args=(cfg, runs, names, kills, random.Random(seed), log), daemon=True)
    t.start()
    res = hycosim_run(cfg, runs, "--restarts", str(kills))
    t.join()
    if res.returncode:
        raise RuntimeError(f"the run with node kills failed: {res.stderr[-2000:]}")
    run = newest_run(runs)
    return run, log, json.loads((run / "meta.json").read_text())


def server_kills(cfg: Path, runs: Path, kills: int, after: float) -> tuple[Path, dict]:
    """A run whose server is killed ``kills`` times, each ``after`` seconds into its life, and resumed
    from its checkpoint: its run directory and meta.json."""
    proc = subprocess.Popen([sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", str(runs), "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
    run, before = None, set(runs.iterdir()) if runs.is_dir() else set()
    for i in range(kills):
        started = time.monotonic()
        # A server killed before its run's first checkpoint leaves nothing to resume: on a loaded
        # machine (the tests in two processes) the first one may come later than ``after``.
        while time.monotonic() - started < 120:
            made = [p for p in runs.iterdir() if p.is_dir() and p not in before] if runs.is_dir() else []
            if made and checkpoints.latest(made[0])[0] is not None:
                break
            time.sleep(0.1)
        time.sleep(max(0.0, after - (time.monotonic() - started)))
        for pid in pids(f"hycosim server {cfg}"):
            os.kill(pid, signal.SIGKILL)
        proc.communicate(timeout=120)
        run = newest_run(runs)
        proc = subprocess.Popen([sys.executable, "-m", "hycosim", "run", str(cfg), "--no-progress", "--resume", str(run)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
    out, err = proc.communicate(timeout=900)
    if proc.returncode:
        raise RuntimeError(f"the resumed run failed: {err[-2000:]}")
    return run, json.loads((run / "meta.json").read_text())


def replay_trial(tmp: Path, stop: float) -> dict:
    """A grasp trial of the paper's scenario, then the same with its camera replayed."""
    from hycosim.scenario.scene_fmus import ensure_scene_fmus

    fmus = ensure_scene_fmus(REPO / "build" / "fmus")
    doc = json.loads((REPO / "hycosim" / "scenario" / "configs" / "grasp-paper.json").read_text())
    doc["serverIP"] = f"127.0.0.1:{free_port()}"
    doc["coSimulation"]["stopTime"] = stop
    for node in doc["nodeLists"]:
        if node.get("fmu"):
            node["fmu"] = str(fmus[node["nodeName"]])
        if node["nodeName"] == "policy":
            node["output"] = [p for p in node["output"] if (p if type(p) is str else p["name"]) != "infer_ms"]
    trial_cfg = tmp / "trial.json"
    trial_cfg.write_text(json.dumps(doc))
    if (res := hycosim_run(trial_cfg, tmp / "trial-runs")).returncode:
        raise RuntimeError(f"the trial failed: {res.stderr[-2000:]}")
    trial = newest_run(tmp / "trial-runs")
    for node in doc["nodeLists"]:
        if node["nodeName"] == "camera":
            node["replay"] = str(trial)
    replay_cfg = tmp / "replayed.json"
    replay_cfg.write_text(json.dumps(doc))
    if (res := hycosim_run(replay_cfg, tmp / "replay-runs")).returncode:
        raise RuntimeError(f"the replay failed: {res.stderr[-2000:]}")
    again = newest_run(tmp / "replay-runs")
    grasped = '"to": "grasp"' in (trial / "events.jsonl").read_text()
    return {"identical": (again / "values.csv").read_bytes() == (trial / "values.csv").read_bytes(),
            "rows": check_rows(trial / "values.csv"), "grasped": grasped,
            "samples": len((trial / "samples.jsonl").read_text().splitlines())}


def ring_rate(n: int, steps: int, every: float | None, tmp: Path) -> float:
    """A ring's steps/s with checkpoints every ``every`` simulated seconds (None: none)."""
    cfg = ring_config(n, steps, tmp / f"ring-{every}.json")
    doc = json.loads(cfg.read_text())
    doc["coSimulation"].update(stepSize=0.001, stopTime=steps * 0.001)
    if every is not None:
        doc["coSimulation"]["checkpointEvery"] = every
    cfg.write_text(json.dumps(doc))
    res = hycosim_run(cfg, tmp / "ring-runs", timeout=300)
    if res.returncode:
        raise RuntimeError(res.stderr[-2000:])
    return float(json.loads((newest_run(tmp / "ring-runs") / "meta.json").read_text())["steps_per_s"])


def main() -> int:
    """Run a reference, the node and server kills (each run's values.csv against the reference's), a
    replay trial and what checkpoints cost; print the figures (``--json``: one object); 0 where every
    run's values came out as the reference's, else 1."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--stop", type=float, default=60.0, help="simulated seconds")
    ap.add_argument("--every", type=float, default=1.0, help="checkpointEvery, simulated seconds")
    ap.add_argument("--node-kills", type=int, default=20)
    ap.add_argument("--server-kills", type=int, default=3)
    ap.add_argument("--replay-stop", type=float, default=2.6, help="simulated seconds of the replayed trial; 0: none")
    ap.add_argument("--ring-steps", type=int, default=20000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", action="store_true")
    _table.add_argument(ap)
    args = ap.parse_args()
    results: dict = {}
    with tempfile.TemporaryDirectory() as tmp_:
        tmp = Path(tmp_)
        cfg = project(tmp, args.stop, args.every)
        names = [n["nodeName"] for n in json.loads(cfg.read_text())["nodeLists"]]
        runs = tmp / "runs"
        runs.mkdir()
        started = time.perf_counter()
        res = hycosim_run(cfg, runs)
        if res.returncode:
            raise SystemExit(f"the reference run failed: {res.stderr[-2000:]}")
        reference = newest_run(runs)
        wall = time.perf_counter() - started
        rows = check_rows(reference / "values.csv")
        ref_bytes = (reference / "values.csv").read_bytes()
        results["reference"] = {"rows": rows, "wall_s": round(wall, 1)}
        if args.node_kills:
            run, log, meta = node_kills(cfg, runs, names, args.node_kills, args.seed)
            recov = [r for r in meta.get("recoveries", []) if r["node"] != "server"]
            secs = sorted(r["seconds"] for r in recov)
            results["node_kills"] = {
                "kills": len(log), "restores": len(recov), "identical": (run / "values.csv").read_bytes() == ref_bytes,
                "rows": check_rows(run / "values.csv"),
                "recovery_s": {"median": statistics.median(secs) if secs else None, "max": max(secs) if secs else None}}
        if args.server_kills:
            run, meta = server_kills(cfg, runs, args.server_kills, max(wall / (args.server_kills + 2), 4.0))
            results["server_kills"] = {
                "resumes": sum(1 for r in meta.get("recoveries", []) if r["node"] == "server"),
                "identical": (run / "values.csv").read_bytes() == ref_bytes, "rows": check_rows(run / "values.csv")}
        if args.replay_stop > 0:
            results["replay"] = replay_trial(tmp, args.replay_stop)
        rates: dict[str, list[float]] = {"without": [], "with": []}
        for _ in range(args.repeat):
            rates["without"].append(ring_rate(2, args.ring_steps, None, tmp))
            rates["with"].append(ring_rate(2, args.ring_steps, 1.0, tmp))
        med = {k: statistics.median(v) for k, v in rates.items()}
        results["checkpoint_cost"] = {"steps_per_s": med, "ratio": med["with"] / med["without"], "rounds": rates}
    _table.write(args.table, _manual_table(args, results))
    if args.json:
        print(json.dumps(results, indent=1))
    else:
        r = results
        print(f"reference: {r['reference']['rows']} steps in {r['reference']['wall_s']} s")
        if "node_kills" in r:
            n = r["node_kills"]
            med, top = (("–" if v is None else f"{v:.2f}") for v in (n["recovery_s"]["median"], n["recovery_s"]["max"]))
            print(f"{n['kills']} node kills, {n['restores']} restores: values.csv identical: {n['identical']}; "
                  f"recovery median {med} s, max {top} s")
        if "server_kills" in r:
            s = r["server_kills"]
            print(f"{s['resumes']} server kills and resumes: values.csv identical: {s['identical']}")
        if "replay" in r:
            p = r["replay"]
            print(f"grasp trial ({p['rows']} steps, {p['samples']} camera samples, grasped: {p['grasped']}) "
                  f"with its camera replayed: values.csv identical: {p['identical']}")
        c = r["checkpoint_cost"]
        print(f"ring N=2, H=1 ms: {c['steps_per_s']['without']:.0f} steps/s without checkpoints, "
              f"{c['steps_per_s']['with']:.0f} with one every 1 s: ratio {c['ratio']:.3f}")
    ok = all(results.get(k, {}).get("identical", True) for k in ("node_kills", "server_kills", "replay"))
    return 0 if ok else 1


def _manual_table(args: argparse.Namespace, r: dict) -> _table.Table:
    rows = []
    if "node_kills" in r:
        n = r["node_kills"]
        loss = n["recovery_s"]
        rows.append([f"{n['kills']} SIGKILLs of random node processes",
                     f"{n['restores']} restores, `values.csv` identical: {n['identical']}; loss to restored run "
                     + (f"{loss['median']:.2f} s median, {loss['max']:.2f} s at most" if loss["median"] is not None
                        else "–")])
    if "server_kills" in r:
        s = r["server_kills"]
        rows.append([f"{args.server_kills} SIGKILL{'s' if args.server_kills != 1 else ''} of the server, each resumed",
                     f"resumed {s['resumes']} times, `values.csv` identical: {s['identical']}"])
    if "replay" in r:
        p = r["replay"]
        rows.append([f"a grasp trial ({p['rows']} steps, {p['samples']} camera samples) replayed with its camera",
                     f"`values.csv` identical: {p['identical']}"])
    c = r["checkpoint_cost"]
    rows.append([f"checkpoints every 1 s on the ring (N = 2, H = 1 ms, {args.ring_steps:,} steps)",
                 f"{c['ratio']:.2f}× the steps/s without"])
    return _table.Table(f"{args.stop:g} s simulated at H = 10 ms ({r['reference']['rows']:,} steps), checkpoints every "
                        f"{args.every:g} s:", ["case", "result"], rows)


if __name__ == "__main__":
    sys.exit(main())
