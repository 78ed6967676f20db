"""The benchmarks run end to end at a small scale and report what --json promises."""

from __future__ import annotations

import importlib
import json
import math
import os
import re
import subprocess
import sys
import time
import uuid

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.helpers import REPO, env
from tests.netns import netns_available

needs_netns = pytest.mark.skipif(not netns_available(), reason="needs root and ip netns")


def manual_tables(path) -> list[list[dict[str, str]]]:
    """The Markdown tables a benchmark wrote with --table (for the manual), each as its rows
    keyed by the header, after checking the line that says how they were measured."""
    lines = path.read_text().splitlines()
    assert lines[0].startswith("`") and time.strftime("%Y-%m-%d") in lines[0] and "--table" not in lines[0], lines[0]
    tables, i = [], 0
    while i < len(lines):
        if lines[i].startswith("| ") and i + 1 < len(lines) and lines[i + 1].startswith("|---"):
            header = [c.strip() for c in lines[i].strip("|").split("|")]
            i += 2
            rows = []
            while i < len(lines) and lines[i].startswith("| "):
                cells = [c.strip() for c in lines[i].strip("|").split("|")]
                assert len(cells) == len(header), lines[i]
                rows.append(dict(zip(header, cells)))
                i += 1
            tables.append(rows)
        i += 1
    assert tables, path.read_text()
    return tables


def test_barrier_benchmark_json_reports_medians_of_its_runs(tmp_path):
    res = subprocess.run([sys.executable, "benchmarks/barrier.py", "--n", "2", "--steps", "200", "--repeat", "2",
                          "--systems", "hycosim", "zenoh-floor", "--json", "--table", str(tmp_path / "barrier.md")],
                         capture_output=True, text=True, timeout=300, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    lines = [json.loads(line) for line in res.stdout.splitlines()]
    assert [(r["system"], r["n"]) for r in lines] == [("hycosim", 2), ("zenoh-floor", 2)]
    for r in lines:
        assert set(r) == {"system", "n", "steps_per_s", "runs"}
        assert len(r["runs"]) == 2 and all(x > 0 for x in r["runs"])
        assert min(r["runs"]) <= r["steps_per_s"] <= max(r["runs"])
    # The manual's table holds the same medians and their ratio, and the range of the rounds'
    # own ratios (round by round: a run's list is in the rounds' order).
    [[row]] = manual_tables(tmp_path / "barrier.md")
    rate = {r["system"]: r["steps_per_s"] for r in lines}
    runs = {r["system"]: r["runs"] for r in lines}
    paired = [a / b for a, b in zip(runs["hycosim"], runs["zenoh-floor"])]
    # (The JSON's rounds are rounded to a tenth, the table's figures made from the unrounded ones.)
    ratio, low, high = re.fullmatch(r"([\d.]+) \(([\d.]+)–([\d.]+)\)", row["hycosim / zenoh-floor"]).groups()
    assert ratio == f"{rate['hycosim'] / rate['zenoh-floor']:.2f}"
    assert abs(float(low) - min(paired)) <= 0.01 and abs(float(high) - max(paired)) <= 0.01
    # Each system's median comes with its lowest and highest round.
    for system in runs:
        median, low, high = re.fullmatch(r"([\d,]+) \(([\d,]+)–([\d,]+)\)", row[system]).groups()
        assert median == f"{rate[system]:,.0f}"
        assert abs(int(low.replace(",", "")) - min(runs[system])) <= 1
        assert abs(int(high.replace(",", "")) - max(runs[system])) <= 1
    text = (tmp_path / "barrier.md").read_text()
    assert "the lowest and highest round" in text and "the lowest and highest of the rounds' own ratios" in text


def test_the_rounds_own_ratios_pair_round_with_round_or_are_not_given():
    round_ratios = _benchmark_module("barrier").round_ratios
    # Round 1: 2.0, round 2: 0.5 — the medians' ratio (1.0) hides both.
    assert round_ratios([4.0, 1.0], [2.0, 2.0], 2) == (0.5, 2.0)
    assert round_ratios([3.0, 1.0, 2.0], [1.0, 2.0, 4.0], 3) == (0.5, 3.0)
    assert round_ratios([1.0], [2.0], 1) is None  # one round: no range
    assert round_ratios([1.0, 2.0], [2.0], 2) is None  # a run failed: the rounds no longer pair
    assert round_ratios([1.0, 2.0], [2.0, 0.0], 2) is None
    # Each lost one of three rounds, not the same one: as long as each other, yet unpaired.
    assert round_ratios([1.0, 2.0], [2.0, 4.0], 3) is None


def test_barrier_benchmark_measures_the_cpu_a_step_costs_every_process_of_a_run(tmp_path):
    res = subprocess.run([sys.executable, "benchmarks/barrier.py", "--n", "2", "--steps", "1000", "--repeat", "1",
                          "--systems", "hycosim", "zenoh-floor", "--cpu", "--json", "--table", str(tmp_path / "b.md")],
                         capture_output=True, text=True, timeout=300, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    lines = {r["system"]: r for r in map(json.loads, res.stdout.splitlines())}
    for r in lines.values():
        assert len(r["cpu_runs"]) == 1 and r["cpu_us_per_step"] == pytest.approx(r["cpu_runs"][0], abs=0.1)
        # Every process of the run counts. On loopback each part of a step's critical path is
        # some process's CPU, so a step's CPU is not far below its wall time (the rate's, taken
        # polling); a quarter of it leaves room for noise, and only the run's own process
        # (the children not counted) would be below it.
        assert 1e6 / r["steps_per_s"] * 0.25 < r["cpu_us_per_step"] < 20_000, r
        # The server's own share: some of the step's CPU, never all of it (the nodes' counts too).
        own, rest = r["cpu_coordinator_us_per_step"], r["cpu_rest_us_per_step"]
        assert len(r["cpu_coordinator_runs"]) == 1 and 0 < own < r["cpu_us_per_step"], r
        assert rest == pytest.approx(r["cpu_us_per_step"] - own, abs=0.1)
    [rates, [row], [own_row], [rest_row]] = manual_tables(tmp_path / "b.md")
    for figure, got in (("cpu_us_per_step", row), ("cpu_coordinator_us_per_step", own_row),
                        ("cpu_rest_us_per_step", rest_row)):
        cost = {s: r[figure] for s, r in lines.items()}
        assert got == {"N": "2", "hycosim": f"{cost['hycosim']:,.0f}", "zenoh-floor": f"{cost['zenoh-floor']:,.0f}",
                       "hycosim / zenoh-floor": f"{cost['hycosim'] / cost['zenoh-floor']:.2f}"}
    text = (tmp_path / "b.md").read_text()
    assert "CPU µs a macro step costs" in text and "the coordinating process alone" in text


def _benchmark_module(name: str):
    """A module of benchmarks/ (not a package), imported with the folder on the path while it loads."""
    sys.path.insert(0, str(REPO / "benchmarks"))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(REPO / "benchmarks"))


def test_a_run_s_processes_share_the_callers_session_and_each_leads_its_own_group():
    """barrier.py starts every process of a run in the benchmark's session (``own_session=False``),
    as a launcher does, so that the scheduler's autogroup takes them as one; each still leads a group
    of its own, which a timeout kills whole (its children with it); by default, a session of its own."""
    import signal

    _procs = _benchmark_module("_procs")
    code = "import os, subprocess, sys, time\n" \
           "child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'])\n" \
           "print(os.getsid(0), os.getpgid(0), child.pid, flush=True)\ntime.sleep(60)"

    def gone(pid: int) -> bool:  # ended: no process, or one left for init to reap
        try:
            with open(f"/proc/{pid}/stat") as f:
                return f.read().rsplit(")", 1)[1].split()[0] == "Z"
        except FileNotFoundError:
            return True

    for own_session in (False, True):
        proc = _procs.start([sys.executable, "-c", code], own_session=own_session, stdout=subprocess.PIPE, text=True)
        try:
            sid, pgid, child = map(int, proc.stdout.readline().split())
            assert pgid == proc.pid and (sid == proc.pid) == own_session and (sid == os.getsid(0)) != own_session
            _procs.kill_group(proc)
            assert proc.wait(timeout=10) == -signal.SIGKILL
            deadline = time.monotonic() + 10
            while not gone(child) and time.monotonic() < deadline:  # the child went with its group
                time.sleep(0.05)
            assert gone(child)
        finally:
            _procs.stop_all(proc)


def test_own_cpu_at_exit_counts_every_thread_of_the_process_and_none_of_its_children():
    own_cpu_at_exit = _benchmark_module("_procs").own_cpu_at_exit
    burn = "import time\ndef burn(s):\n    t = time.thread_time()\n    while time.thread_time() - t < s: pass\n"
    code = (burn + "import subprocess, sys, threading\nth = threading.Thread(target=burn, args=(0.3,)); th.start()\n"
            "burn(0.2); th.join()\nsubprocess.run([sys.executable, '-c', " + repr(burn + "burn(0.6)") + "])\n")
    proc = subprocess.Popen([sys.executable, "-c", code])
    own = own_cpu_at_exit(proc, timeout=60)
    assert proc.wait() == 0  # not reaped by own_cpu_at_exit
    # Both threads' 0.5 s and the interpreter's start, not the child's 0.6 s.
    assert 0.45 <= own < 1.0, own


def _tagged(tag: str) -> list[int]:
    """The processes running with ``tag`` in their environment (what one test's run started,
    whichever other tests run beside it)."""
    found = []
    for entry in os.listdir("/proc"):
        try:
            with open(f"/proc/{entry}/environ", "rb") as f:
                if tag.encode() in f.read().split(b"\0"):
                    found.append(int(entry))
        except (OSError, ValueError):
            continue
    return found


def test_barrier_benchmark_kills_a_run_past_its_timeout_and_says_so():
    # Steps enough that neither finishes in 0.5 s (200 floor steps did, on a machine at rest).
    tag = f"HYCOSIM_TEST_RUN={uuid.uuid4().hex}"
    res = subprocess.run([sys.executable, "benchmarks/barrier.py", "--n", "2", "--steps", "1000000", "--repeat", "1",
                          "--systems", "hycosim", "zenoh-floor", "--timeout", "0.5"],
                         capture_output=True, text=True, timeout=120, cwd=REPO,
                         env=dict(env(), HYCOSIM_TEST_RUN=tag.split("=", 1)[1]))
    assert res.returncode == 1
    assert "# hycosim n=2: failed:\ntimed out after 0.5 s (--timeout)" in res.stderr
    assert "# zenoh-floor n=2: failed:\ntimed out after 0.5 s (--timeout)" in res.stderr
    assert "# no run completed for hycosim N=2, zenoh-floor N=2" in res.stderr
    assert "hycosim N=2: 0 of 1" in res.stdout
    # The server and nodes of the killed runs went with them (every process the run started
    # carries its tag; another test's floor may run beside this one).
    time.sleep(0.5)
    left = _tagged(tag)
    assert left == []


def test_fmu_overhead_benchmark_runs_every_measurement(tmp_path):
    res = subprocess.run([sys.executable, "benchmarks/fmu_overhead.py", "--steps", "200", "--repeat", "2", "--json",
                          "--table", str(tmp_path / "fmu.md")],
                         capture_output=True, text=True, timeout=300, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    figures = json.loads(res.stdout.splitlines()[-1])
    assert set(figures) == {"python_node_step_us", "fmu_node_step_us", "python_node_cosim_steps_per_s",
                            "fmu_node_cosim_steps_per_s", "bridge_fmu_cosim_steps_per_s", "zenoh_floor_steps_per_s",
                            "me_node_step_us", "fmpy_me_step_us"}
    assert all(v > 0 for v in figures.values())
    # pythonfmu through fmpy does more per step than a plain method call, whatever the machine.
    assert figures["fmu_node_step_us"] > figures["python_node_step_us"]
    [rows] = manual_tables(tmp_path / "fmu.md")
    assert [r["what"] for r in rows] == ["one step of the gain model", "a one-node co-simulation", "a round trip",
                                         "Model Exchange (the bouncing ball, 10 ms)"]
    assert rows[3]["ratio"] == f"{figures['me_node_step_us'] / figures['fmpy_me_step_us']:.2f}×"


def test_fmu_overhead_benchmark_kills_a_cosimulation_past_its_timeout_and_says_which(tmp_path):
    # Steps enough that the first co-simulation cannot finish in 0.5 s (200 did, once, beside other tests).
    res = subprocess.run([sys.executable, "benchmarks/fmu_overhead.py", "--steps", "20000", "--timeout", "0.5"],
                         capture_output=True, text=True, timeout=120, cwd=REPO, env=env())
    assert res.returncode == 1
    assert "fmu_overhead: the Python node's co-simulation failed: timed out after 0.5 s (--timeout)" in res.stderr
    # Its server and node went with it (they run the benchmark's project, bench-*).
    time.sleep(0.5)
    left = subprocess.run(["pgrep", "-f", "hycosim (run|server|node) .*py.json"], capture_output=True, text=True)
    assert left.stdout.split() == []


@needs_netns
def test_scale_benchmark_over_namespaces_reports_and_kills_a_run_past_its_timeout():
    res = subprocess.run([sys.executable, "benchmarks/scale.py", "--n", "2", "4", "--steps", "100", "--hosts", "2",
                          "--json"], capture_output=True, text=True, timeout=300, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    lines = [json.loads(line) for line in res.stdout.splitlines()]
    assert [(r["system"], r["n"]) for r in lines] == [("hycosim-netns", 2), ("hycosim-netns", 4)]
    assert all(r["steps_per_s"] > 0 for r in lines)
    res = subprocess.run([sys.executable, "benchmarks/scale.py", "--n", "2", "--steps", "1000000", "--hosts", "2",
                          "--timeout", "3"], capture_output=True, text=True, timeout=120, cwd=REPO, env=env())
    assert res.returncode == 1 and "scale: N=2: timed out after 3 s (--timeout)" in res.stderr
    time.sleep(0.5)  # the server and nodes went with it, though their namespaces did
    left = subprocess.run(["pgrep", "-f", "hycosim (server|node) .*scale-ring.json"], capture_output=True, text=True)
    assert left.stdout.split() == []


def test_memory_benchmark_reports_peaks_growth_and_ratios(tmp_path):
    res = subprocess.run([sys.executable, "benchmarks/memory.py", "--n", "2", "--steps", "300", "--json",
                          "--table", str(tmp_path / "memory.md")],
                         capture_output=True, text=True, timeout=300, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    lines = [json.loads(line) for line in res.stdout.splitlines()]
    peaks, summary = lines[:-1], lines[-1]
    kinds = {"hycosim": ("server", "node", "report", "plot"), "zenoh-floor": ("server", "node")}
    assert sorted((r["system"], r["process"], r["steps"]) for r in peaks) == sorted(
        (system, kind, steps) for system in kinds for kind in kinds[system] for steps in (300, 3000))
    assert all(20 < r["peak_rss_mib"] < 2000 for r in peaks)  # a Python process with zenoh, not a stray one
    rss = {(r["system"], r["process"], r["steps"]): r["peak_rss_mib"] for r in peaks}
    assert summary["vs_floor"]["server"] == pytest.approx(
        rss[("hycosim", "server", 3000)] / rss[("zenoh-floor", "server", 3000)], abs=0.01)
    assert set(summary["growth"]) == {f"{system} {kind}" for system in kinds for kind in kinds[system]}
    assert all(0.8 < g < 1.5 for g in summary["growth"].values())
    [rows] = manual_tables(tmp_path / "memory.md")
    assert [r["process"] for r in rows] == ["server", "node", "report", "plot"]
    assert rows[0]["hycosim, 3,000 steps"] == f"{rss[('hycosim', 'server', 3000)]:.1f}"
    assert rows[1]["hycosim / bare"] == f"{summary['vs_floor']['node']:.2f}" and rows[2]["hycosim / bare"] == "–"


def test_a_python_node_process_loads_neither_fmpy_nor_numpy():
    # What a node playing a Python model imports (hycosim.node.main and what it loads for a gain).
    code = ("import sys, hycosim.node.main, hycosim.node.loader, hycosim.node.reference.gain; "
            "print(sorted(m for m in ('fmpy', 'numpy', 'torch', 'mujoco', 'cv2') if m in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]"



def test_fuzz_benchmark_reports_an_unharmed_run_at_a_small_scale(tmp_path):
    res = subprocess.run([sys.executable, "benchmarks/fuzz.py", "--frames", "1000", "--streams", "10",
                          "--forged", "300", "--seconds", "1.5", "--json", "--table", str(tmp_path / "fuzz.md")],
                         capture_output=True, text=True, timeout=300, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    fuzz, forgery = (json.loads(line) for line in res.stdout.splitlines())
    assert fuzz["experiment"] == "fuzz" and fuzz["frames"] == 1000 and fuzz["all_sent_during_run"]
    assert fuzz["exit_code"] == 0 and fuzz["identical_values"] and fuzz["dropped_total"] > 0
    assert fuzz["server_log_bytes"] < 1 << 20
    assert forgery["exit_code"] == 0 and forgery["identical_values"] and forgery["all_sent_during_run"]
    assert forgery["reached_server"] == 0 and forgery["reached_nodes"] == 0 and sum(forgery["by_key"].values()) == 300
    [rows] = manual_tables(tmp_path / "fuzz.md")
    assert [(r["exit"], r["`values.csv` identical"]) for r in rows] == [("0", "True"), ("0", "True")]
    assert rows[1]["what became of it"] == "reached the server: 0; reached a node: 0"


def test_status_flood_benchmark_reports_the_floods_cost_and_that_the_server_said_busy(tmp_path):
    # Steps enough that the flooder, which can connect only once the run's server listens, asks
    # while the run lasts on a loaded machine too (at 1,500 it once never did).
    res = subprocess.run([sys.executable, "benchmarks/status_flood.py", "--steps", "6000", "--repeat", "1", "--json",
                          "--table", str(tmp_path / "flood.md")],
                         capture_output=True, text=True, timeout=300, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    r = json.loads(res.stdout)
    assert set(r["ratio_to_plain"]) == {"plain", "busy core", "flood, waiting", "flood, firing"}
    assert r["ratio_to_plain"]["plain"] == 1.0 and all(v > 0 for v in r["median_steps_per_s"].values())
    for kind, f in r["floods"].items():
        # questions past the budget were answered busy, and the server counted refusals (the
        # two tallies are not compared here: the flooder's is printed twice a second and it asks
        # on after the server's records close; tests/test_wire_live.py compares them exactly)
        assert f["answered"][0] >= 1 and f["busy"][0] > 0 and f["counted_busy"][0] > 0, (kind, f)
    assert r["floods"]["flood, waiting"]["busy"][0] > r["floods"]["flood, waiting"]["answered"][0]
    [rows] = manual_tables(tmp_path / "flood.md")
    assert [(x["beside the run"], x["against plain"]) for x in rows][0] == ("plain", "1.00")
    assert rows[2]["told busy"] == f"{r['floods']['flood, waiting']['busy'][0]:,}" and rows[1]["told busy"] == "–"


def test_recovery_benchmark_reports_identical_records_at_a_small_scale(tmp_path):
    res = subprocess.run([sys.executable, "benchmarks/recovery.py", "--stop", "10", "--every", "0.5", "--node-kills", "2",
                          "--server-kills", "1", "--replay-stop", "0", "--ring-steps", "2000", "--repeat", "1",
                          "--json", "--table", str(tmp_path / "recovery.md")],
                         capture_output=True, text=True, timeout=400, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    r = json.loads(res.stdout)
    assert r["reference"]["rows"] == 1001
    kills = r["node_kills"]
    # A short run may end before the second kill; every kill that lands mid-run is one restore.
    assert 1 <= kills["restores"] <= kills["kills"] <= 2 and kills["identical"] and kills["rows"] == 1001
    assert 0 < kills["recovery_s"]["max"] < 30
    assert r["server_kills"] == {"resumes": 1, "identical": True, "rows": 1001}
    assert r["checkpoint_cost"]["ratio"] > 0
    assert "replay" not in r  # tests/test_replay.py runs the replayed trial
    [rows] = manual_tables(tmp_path / "recovery.md")
    assert [x["case"] for x in rows[:2]] == ["2 SIGKILLs of random node processes",
                                             "1 SIGKILL of the server, each resumed"]
    assert "`values.csv` identical: True" in rows[0]["result"]
    assert rows[1]["result"] == "resumed 1 times, `values.csv` identical: True"
    assert rows[2]["result"] == f"{r['checkpoint_cost']['ratio']:.2f}× the steps/s without"


def test_accuracy_benchmark_compares_the_couplings_with_the_exact_solution_and_counts_messages(tmp_path):
    # In process: every figure but the wall times is the one runs in processes give (make bench
    # runs it so), without starting some 50 processes.
    res = subprocess.run([sys.executable, "benchmarks/accuracy.py", "--in-process", "--stop", "0.5", "--h", "0.01",
                          "--mr-stop", "0.3", "--transient-stop", "1.1", "--fixed-h", "0.002", "--tolerances", "1e-4",
                          "--plot", str(tmp_path / "accuracy.png"), "--json", "--table", str(tmp_path / "acc.md")],
                         capture_output=True, text=True, timeout=300, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    r = json.loads(res.stdout)
    for problem in ("two", "three"):  # each split across FMUs, one node process a mass
        by = {row["coupling"]: row for row in r["oscillator"] if row["problem"] == problem}
        assert set(by) == {"jacobi", "gauss-seidel", "iterative", "interpolated-1", "interpolated-2", "interpolated-3"}
        # Polynomials of degree n start on n − 1 macro steps taken as 8 each.
        assert [by[s]["macro_steps"] for s in by] == [50, 50, 50, 50, 57, 64]
        assert 0 < by["gauss-seidel"]["error_x1"] < by["jacobi"]["error_x1"] < 0.2  # x1 swings ±0.1 m
        assert 0 < by["iterative"]["error_x1"] < by["jacobi"]["error_x1"] and by["iterative"]["takes"] > 50
        # Inputs moving over the step: each degree better; a cubic's as good as RK4 on the whole system.
        errors = [by[f"interpolated-{n}"]["error_x1"] for n in (1, 2, 3)]
        assert 0 < errors[2] < errors[1] < errors[0] < by["iterative"]["error_x1"] / 10
        mono = next(m for m in r["monolithic_rk4"] if m["problem"] == problem)
        assert mono["macro_steps"] == 50 and errors[2] < 3 * mono["error_x1"]
        assert r["gs_over_jacobi_error"][problem]["0.01"] == by["gauss-seidel"]["error_x1"] / by["jacobi"]["error_x1"]
    fixed, controlled = r["transient"]
    assert fixed["macro_steps"] == 550 and fixed["takes"] == 550
    # At rest until the pulse at 1 s, the controlled step grows; at the pulse it is taken again shorter.
    assert controlled["macro_steps"] < fixed["macro_steps"] and controlled["rejected"] > 0
    assert 0 < controlled["error_x1"] < 0.01 and 0 < fixed["error_x1"] < 0.01
    assert (tmp_path / "accuracy.png").stat().st_size > 20_000
    m = r["multirate"]
    # 0.3 s at 1 ms: a release per base point unless batched over the 100 Hz node's 10 base steps.
    assert m["single_rate"]["releases"] == m["multi_rate_unbatched"]["releases"] == 300
    assert m["multi_rate"]["releases"] == 30 and "batched over 10 base steps" in m["multi_rate"]["coupling"]
    assert m["single_rate"]["points"] == m["multi_rate"]["points"] == 301
    assert m["multi_rate"]["messages"] < m["multi_rate_unbatched"]["messages"] < m["single_rate"]["messages"]
    assert m["message_ratio"] <= 1 / 3 and m["fast_node_identical"] and m["batching_changes_nothing"]
    schemes, rates, control = manual_tables(tmp_path / "acc.md")
    assert [(x["masses"], x["H"]) for x in schemes] == [("two", "10 ms"), ("three", "10 ms")]
    two = {row["coupling"]: row for row in r["oscillator"] if row["problem"] == "two"}
    assert schemes[0]["Jacobi"] == f"{two['jacobi']['error_x1']:.2e} m"
    assert schemes[0]["degree 3"] == f"{two['interpolated-3']['error_x1']:.2e} m ({two['interpolated-3']['takes']:,})"
    assert rates == [{"frames multi-rate": f"{m['multi_rate']['messages']:,}",
                      "frames all at 1 kHz": f"{m['single_rate']['messages']:,}", "ratio": f"{m['message_ratio']:.3f}",
                      "the fast node's values identical": "True", "`values.csv` the same unbatched": "True"}]
    assert [x["step"] for x in control] == ["H = 0.002 s", "tolerance 0.0001"]


_odd = st.sampled_from([float("nan"), float("inf"), -1.0, 1.0000001, "1", "x", None, True, [], {}])
_point = st.fixed_dictionaries({"seconds": st.floats(0, 1e4), "mean_success": st.floats(0, 1)},
                               optional={"episode": st.integers(0, 10**6),
                                         "per_angle": st.dictionaries(st.sampled_from("3456"), st.floats(0, 1))})
_curves = st.dictionaries(st.text(max_size=8), st.lists(_point, max_size=4), max_size=3)
# A file --save wrote, and at most one fault put into it.
_fault = st.none() | st.tuples(st.integers(0, 20), st.sampled_from(["seconds", "mean_success"]), _odd | st.just(...)) \
    | st.sampled_from(["no paper", "paper a list", "a list", "cut", "not UTF-8"])


@given(paper=_curves, ours=_curves, fault=_fault)
def test_the_baselines_saved_curves_are_read_back_whole_or_refused_by_name(paper, ours, fault):
    import copy

    from benchmarks.policy_baseline import parse_paper_curves

    doc = {"paper": copy.deepcopy(paper), "ours": ours}
    points = [p for run in doc["paper"].values() for p in run]
    if isinstance(fault, tuple) and points:
        point = points[fault[0] % len(points)]
        if fault[2] is ...:
            del point[fault[1]]
        else:
            point[fault[1]] = fault[2]
    elif fault == "no paper":
        del doc["paper"]
    elif fault == "paper a list":
        doc["paper"] = points
    data = json.dumps([doc] if fault == "a list" else doc).encode()
    data = data[: len(data) // 2] if fault == "cut" else b"\xff" + data if fault == "not UTF-8" else data
    try:
        curves = parse_paper_curves(data, "saved.json")
    except ValueError as exc:
        assert str(exc).startswith("saved.json: not a file of curves written by --save (")
        assert fault is not None and (not isinstance(fault, tuple) or points)
        return
    # What is read back is the file's curves, every point one the plot can draw.
    assert not isinstance(fault, str)
    assert list(curves) == list(doc["paper"])
    for label, run in curves.items():
        assert [(e["seconds"], e["mean_success"]) for e in run] == [
            (float(p["seconds"]), float(p["mean_success"])) for p in doc["paper"][label]]
        assert all(math.isfinite(e["seconds"]) and e["seconds"] >= 0 and 0 <= e["mean_success"] <= 1 for e in run)


def test_dashboard_cost_benchmark_reports_the_cost_the_latency_and_what_watching_takes(tmp_path):
    res = subprocess.run([sys.executable, "benchmarks/dashboard_cost.py", "--steps", "500", "--repeat", "1",
                          "--least-page", "--page-elsewhere", "--wait-strategy", "block", "--paced-s", "10", "--big",
                          "2000", "--json", "--table", str(tmp_path / "dash.md")],
                         capture_output=True, text=True, timeout=400, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    assert got["ratio"] == got["median_dashboard"] / got["median_plain"] > 0
    # Beside them, the plain run with a browser showing the least page: what any page costs.
    assert got["least_page_ratio"] == got["median_least_page"] / got["median_plain"] > 0
    # And with the dashboard feeding a page elsewhere, which got its snapshots.
    assert got["page_elsewhere_ratio"] == got["median_page_elsewhere"] / got["median_plain"] > 0
    assert len(got["page_elsewhere_snapshots"]) == 1 and got["page_elsewhere_snapshots"][0] >= 1
    assert got["wait_strategy"] == "block" and [len(r) for r in got["steps_per_s"].values()] == [1, 1, 1, 1]
    # The paced run's 1,000 steps reach the page, each within seconds of its point at the server.
    lat = got["latency_ms"]
    assert lat["steps"] >= 900 and 0 < lat["median"] <= lat["p95"] < 5000
    w = got["watching"]
    assert 3 <= w["updates_per_s"] <= 21  # the page is pushed 5 to 20 times a second
    assert w["browser"] > 0 and w["dashboard"] > 0 and w["browser_floor"] > 0
    assert w["cores"] >= 1
    big = got["big_run"]
    assert 0 < big["usable_s"] <= big["plot_s"] and big["points_sent"] > 100
    [rows] = manual_tables(tmp_path / "dash.md")
    assert [x["case"] for x in rows] == ["the dashboard and its page here", "any page here (one line, 5/s)",
                                         "the dashboard, its page on another machine", "a step reaches the page",
                                         "a finished run of 2,000 steps"]
    assert rows[0]["figure"].startswith(f"{got['ratio']:.3f} (")


def test_inprocess_benchmark_reports_ratios_against_the_distributed_run_and_ecos_and_identical_values(tmp_path):
    res = subprocess.run([sys.executable, "benchmarks/inprocess.py", "--n", "2", "--ring-steps", "1500",
                          "--fmu-steps", "1500", "--repeat", "1", "--json", "--table", str(tmp_path / "inproc.md")],
                         capture_output=True, text=True, timeout=300, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    r = json.loads(res.stdout)
    assert r["ecos"], "ECOS is a test dependency (ecospy, libtbb12): the comparison must run"
    assert r["values_identical"] == {"ring N=2": True, "3 FMUs": True}
    assert set(r["ratios"]) == {"ring N=2 in process / processes", "3 FMUs hycosim in process / ECOS",
                                "3 FMUs hycosim processes / ECOS", "3 FMUs fmpy loop / ECOS",
                                "3 FMUs hycosim.open / in process"}
    assert all(v > 0 for v in r["median_steps_per_s"].values())
    [rows] = manual_tables(tmp_path / "inproc.md")
    assert [(x["system"], x["`values.csv` identical"]) for x in rows] == [("ring N=2", "True"), ("3 FMUs", "True")]
    assert rows[1]["ECOS"] == f"{r['median_steps_per_s']['3 FMUs ECOS']:,.0f}"
    assert rows[1]["`hycosim.open`"] == f"{r['median_steps_per_s']['3 FMUs hycosim.open']:,.0f}"
    assert rows[1]["ratio"] == f"{r['ratios']['3 FMUs hycosim in process / ECOS']:.2f}× ECOS"


def test_crosscheck_benchmark_finds_hycosim_ecos_and_libcosim_equal_at_t0_and_within_rounding_after(tmp_path):
    res = subprocess.run([sys.executable, "benchmarks/crosscheck.py", "--steps", "80", "--json",
                          "--table", str(tmp_path / "cross.md")],
                         capture_output=True, text=True, timeout=600, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    r = json.loads(res.stdout)
    assert set(r) == {"chain", "late", "ball", "vdp", "bounce", "override", "chain1", "ball1", "vdp1", "osp"}
    # An OSP system structure run from its XML in hycosim and libcosim: initial values, a
    # multi-rate simulator, a linear transformation, a sum of one, equal within rounding at every
    # point; the algebraic loop parts at t0 (libcosim's initialisation stops after a fixed number
    # of passes, hycosim's at the fixed point) and meets again as the Jacobi steps converge.
    assert set(r["osp"]) == {"hycosim in process", "libcosim"}
    loop = {"loopA.y", "loopA.u", "loopB.y", "loopB.u"}
    for var, v in r["osp"]["libcosim"].items():
        if var in loop:
            assert 0.01 < v["max_abs_diff"] < 0.1 and v["last_diff"] < 1e-9, (var, v)
        else:
            assert v["t0_diff"] in (0.0, None) and v["max_rel_diff"] <= 1e-12, (var, v)
    assert r["osp"]["libcosim"]["ball.bounces"]["points"] >= 80  # the multi-rate ball at every point
    # A scenario's override and release, against libcosim's override manipulator: the input
    # overridden, and what follows from it, equal at every point (ECOS has no override).
    assert set(r["override"]) == {"hycosim in process", "libcosim"}
    # Without the override libcosim's ft.u would part from hycosim's by about 3 over a quarter of the run.
    for var in ("ft.u", "ft.y", "ft2.u", "ft2.y"):
        assert r["override"]["libcosim"][var]["max_rel_diff"] <= 1e-12, var
        assert r["override"]["hycosim in process"][var]["max_abs_diff"] == 0.0, var
    for name in ("vdp", "bounce"):
        assert set(r[name]) == {"hycosim in process", "ECOS", "libcosim", "fmpy.simulate_fmu"}
        assert all(v["max_abs_diff"] == 0.0 for v in r[name]["fmpy.simulate_fmu"].values())
    for name, system in r.items():
        assert all(v["max_abs_diff"] == 0.0 for v in system["hycosim in process"].values())
        if name in ("override", "osp"):
            continue  # above
        assert {"ECOS", "libcosim"} - ({"libcosim"} if name == "ball1" else set()) <= set(system), name
        for engine in {"ECOS", "libcosim"} & set(system):
            for var, v in system[engine].items():
                assert v["t0_diff"] in (0.0, None) and v["max_rel_diff"] <= 1e-12, (name, engine, var, v)
                assert v["points"] >= 80
    # The ball's first contact (t = 0.45 s) lies in the run: its count, its flag and their
    # feedthroughs are equal everywhere; the parameters the package binds (e, gain, offset)
    # took in every engine, or the values would part by far more than rounding.
    for engine in ("ECOS", "libcosim"):
        for var in ("ball.bounces", "ball.falling", "types.iy", "types.by", "types.iu", "types.bu"):
            assert r["ball"][engine][var]["max_abs_diff"] == 0.0, (engine, var)
    assert r["ball"]["libcosim"]["ball.falling"]["t0_diff"] is None  # libcosimpy: no Boolean at t0
    assert r["chain"]["ECOS"]["ft.y"]["compared"].startswith("one point earlier")
    # Feedthroughs that compute only on leaving initialisation mode and in their steps: their
    # start inputs were set inside that mode, as ECOS and libcosim set them, or ft1.y at t0 (7
    # there) and ft2.y from the first step on would part from theirs by 7.
    for engine in ("ECOS", "libcosim"):
        for var in ("ft1.y", "ft2.y", "ft1.u", "ft2.u"):
            assert r["late"][engine][var]["max_abs_diff"] == 0.0, (engine, var)
    assert r["late"]["ECOS"]["ft1.y"]["t0_diff"] == 0.0
    # FMI 1.0 builds of the same models (fmpy's FMI 1.0 classes): equal to ECOS's and libcosim's
    # as the FMI 2.0 builds are, and the oscillator to fmpy.simulate_fmu's to the bit.
    assert all(v["max_abs_diff"] == 0.0 for v in r["vdp1"]["fmpy.simulate_fmu"].values())
    for var in ("ball.bounces", "ball.falling", "types.iy", "types.by"):
        assert r["ball1"]["ECOS"][var]["max_abs_diff"] == 0.0, var
    assert r["chain"]["libcosim"]["ft.u"]["compared"].startswith("one point later")
    rows = manual_tables(tmp_path / "cross.md")[0]
    assert [(x["system"], x["engine"]) for x in rows] == [(name, engine) for name, system in r.items() for engine in system]
    assert {x["largest difference"] for x in rows if x["engine"] == "hycosim in process"} == {"0"}
    assert all(x["at t0"] == "0" for x in rows if x["engine"] == "ECOS")


def test_scene_fmus_benchmark_writes_the_manuals_table(tmp_path):
    res = subprocess.run([sys.executable, "benchmarks/scene_fmus.py", "--seconds", "0.5", "--json",
                          "--table", str(tmp_path / "scene.md")],
                         capture_output=True, text=True, timeout=300, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    figures = {r["model"]: r for r in map(json.loads, res.stdout.splitlines())}
    [rows] = manual_tables(tmp_path / "scene.md")
    assert [x["model"] for x in rows] == ["rod", "robot"]
    assert [x["FMU cost (goal < 2×)"] for x in rows] == [f"{figures[m]['cost_ratio']:.2f}×" for m in ("rod", "robot")]


def test_every_benchmark_make_bench_runs_writes_a_table_a_manual_page_includes():
    """make bench regenerates the manual's figures: each script it runs writes the file that one
    page names, and each page's named file is one make bench writes (and is in the repository)."""
    import re

    written = re.findall(r"benchmarks/(\w+)\.py [^\n]*--table benchmarks/results/(\w+)\.md", (REPO / "Makefile").read_text())
    assert [a for a, b in written] == [b for a, b in written] and len(written) >= 11
    included = re.findall(r"<!-- bench: (\w+) -->", "".join(p.read_text() for p in (REPO / "docs").glob("*.md")))
    assert sorted(included) == sorted(a for a, _ in written)
    for name in included:
        lines = (REPO / "benchmarks" / "results" / f"{name}.md").read_text().splitlines()
        assert lines[0].startswith(f"`{name}.py") and any(line.startswith("|---") for line in lines)


def test_recording_benchmark_measures_csv_and_parquet_against_csv_in_the_same_run(tmp_path):
    res = subprocess.run([sys.executable, "benchmarks/recording.py", "--steps", "2000", "--repeat", "1", "--json",
                          "--table", str(tmp_path / "recording.md")],
                         capture_output=True, text=True, timeout=300, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    result = json.loads(res.stdout)
    assert result["columns"] == 53 and set(result["us_per_point"]) == {
        "csv", "csv, rows in a process of their own", "parquet"}
    assert result["vs_csv"]["csv"] == 1.0 and all(v > 0 for v in result["us_per_point"].values())
    assert all(b > 2000 * 50 for b in result["bytes"].values())  # every point's 50 values are on disk
    [rows] = manual_tables(tmp_path / "recording.md")
    assert [r["format"] for r in rows] == ["csv", "csv, rows in a process of their own", "parquet"]
    assert rows[2]["time × csv"] == f"{result['vs_csv']['parquet']:.2f}"


def test_decode_benchmark_measures_msgspec_and_the_floor_against_todays_decode_per_kind(tmp_path):
    res = subprocess.run([sys.executable, "benchmarks/decode.py", "--n", "2", "8", "--repeat", "1", "--count", "300",
                          "--json", "--table", str(tmp_path / "decode.md")],
                         capture_output=True, text=True, timeout=300, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    rows = [json.loads(line) for line in res.stdout.splitlines()]
    assert {(r["kind"], r["n"], r["system"]) for r in rows} == {
        (k, n, s) for k in ("OUTPUTS", "STEP", "BATCH") for n in (2, 8)
        for s in ("frames.decode", "msgspec", "msgpack floor")}
    assert all(r["ns"] > 0 for r in rows) and all(r["ratio"] == 1.0 for r in rows if r["system"] == "frames.decode")
    [table] = manual_tables(tmp_path / "decode.md")
    assert len(table) == len(rows)


def test_sweep_benchmark_runs_the_same_variants_in_a_loop_and_on_one_and_two_workers(tmp_path):
    res = subprocess.run([sys.executable, "benchmarks/sweep.py", "--runs", "4", "--steps", "20", "--json",
                          "--table", str(tmp_path / "sweep.md")],
                         capture_output=True, text=True, timeout=300, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr
    result = json.loads(res.stdout.splitlines()[-1])
    assert set(result["seconds"]) == {"plain loop of hycosim.open", "sweep, 1 worker", "sweep, 2 workers"}
    assert all(s > 0 for s in result["seconds"].values()) and result["two_vs_one"] > 0
    [rows] = manual_tables(tmp_path / "sweep.md")
    assert [r["way"] for r in rows] == list(result["seconds"]) and rows[0]["× plain loop"] == "1.00"


def test_trials_benchmark_runs_the_same_trials_one_after_another_and_on_dask_workers(tmp_path):
    res = subprocess.run([sys.executable, "benchmarks/trials.py", "--angles", "40", "--trials", "1", "--workers", "1",
                          "--json", "--table", str(tmp_path / "trials.md")],
                         capture_output=True, text=True, timeout=300, cwd=REPO, env=env())
    assert res.returncode == 0, res.stderr[-2000:]
    ways = json.loads(res.stdout.splitlines()[-1])
    assert list(ways) == ["one after another", "1 Dask worker"]
    assert all(w["trials"] == 1 and w["seconds"] > 0 and w["success_pct"] == 100 for w in ways.values())
    [rows] = manual_tables(tmp_path / "trials.md")
    assert [r["way"] for r in rows] == list(ways) and rows[0]["× serial"] == "1.00"
    ratio = ways["1 Dask worker"]["seconds"] / ways["one after another"]["seconds"]
    assert rows[1]["× serial"] == f"{ratio:.2f}"
