"""Where the time goes: report, plot and real-time pacing on real runs."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.helpers import hycosim, meta, read_rows, run_project, write_project


def test_report_names_the_node_that_holds_the_barrier_and_plot_draws(tmp_path):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "fast", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
        # 8 ms of work a step: with 4 ms, a preempted "fast" node held a quarter of the steps
        # once, on a machine running two test processes and a third load.
        {"nodeName": "slow", "UID": 3, "model": "gain", "parameters": {"work_s": 0.008}, "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "fast.u"}, {"from": "clock.y", "to": "slow.u"}],
        events=[{"name": "late", "when": "clock.y >= 0.5 and clock.y < 0.8", "drives": "fast", "until": "clock.y >= 0.8"}],
        cosim={"stepSize": 0.01, "stopTime": 1.0})
    run = run_project(cfg, tmp_path / "runs")
    res = hycosim("report", str(run), "--json")
    assert res.returncode == 0, res.stderr
    s = json.loads(res.stdout)
    assert s["steps"] == 101 and s["status"] == "completed"
    assert max(s["holder_share"], key=s["holder_share"].get) == "slow"
    assert s["holder_share"]["slow"] > 0.8
    # The slow node's 8 ms of work a step (the start has none); the fast node answers sooner. Only
    # the order is held to: in one make test a loaded machine made the fast one's mean 5.3 ms.
    assert s["mean_arrival_ms"]["slow"] > 7.0 and s["mean_arrival_ms"]["fast"] < s["mean_arrival_ms"]["slow"]
    assert [e["to"] for e in s["mode_switches"]] == ["late", "free"]
    # the ranking is the report's; who held each step is the scheduler's, so a stray
    # preemption of another node may own one of them on a loaded machine
    slowest = s["slowest_steps"]
    waits = [row["wait_ms"] for row in slowest]
    assert len(slowest) == 5 and waits == sorted(waits, reverse=True)
    by_step = {int(r["step"]): r for r in read_rows(run, "timing.csv")}
    assert all(by_step[row["step"]]["holder"] == row["holder"] for row in slowest)
    assert min(waits) >= max(1000 * float(r["wait_s"]) for n, r in by_step.items()
                             if n > 0 and n not in {row["step"] for row in slowest})
    assert sum(row["holder"] == "slow" for row in slowest) >= 3
    # Every frame the server read is counted once: at least 3 outputs at each of 101 points.
    assert s["wait_strategy"] == "auto" and set(s["server_waits"]) == {"queued", "polled", "slept"}
    assert sum(s["server_waits"].values()) >= 303 and s["server_waits"]["slept"] > 0  # waiting for slow
    text = hycosim("report", str(run))
    assert text.returncode == 0 and "who held the barrier" in text.stdout and "slow" in text.stdout
    assert "how the server had its" in text.stdout and "% slept" in text.stdout
    png = tmp_path / "plot.png"
    res = hycosim("plot", str(run), "clock.y", "slow.y", "-o", str(png))
    assert res.returncode == 0, res.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    bad = hycosim("plot", str(run), "clock.nope")
    assert bad.returncode == 2 and "no recorded port clock.nope" in bad.stderr
    misspelt = hycosim("plot", str(run), "slow.yy")
    assert misspelt.returncode == 2 and "no recorded port slow.yy; did you mean 'slow.y'?" in misspelt.stderr
    missing = hycosim("report", str(tmp_path / "nowhere"))
    assert missing.returncode == 2 and "not a run directory" in missing.stderr


def test_real_time_pacing_follows_the_wall_clock(tmp_path):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}], cosim={"stepSize": 0.02, "stopTime": 1.0, "realTime": 0.5})
    run = run_project(cfg, tmp_path / "runs")
    m = meta(run)
    # factor 0.5: one simulated second in half a wall second, not faster
    assert 0.49 < m["wall_time_s"]
    assert m["steps_per_s"] < 2 * 50 / 0.5 * 1.1
    timing = read_rows(run, "timing.csv")
    lateness = [float(r["lateness_s"]) for r in timing]
    assert len(lateness) == 51 and all(x >= 0 for x in lateness)
    s = json.loads(hycosim("report", str(run), "--json").stdout)
    assert s["lateness"]["steps"] == 50  # the start-up point is not a macro step


def test_a_run_cut_off_mid_write_still_reports_and_plots_what_it_finished(tmp_path):
    from hycosim.core.run_files import read_csv_rows

    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}],
        events=[{"name": "hold", "when": "clock.y >= 0.3", "drives": "g", "until": "clock.y >= 0.6"}],
        cosim={"stepSize": 0.01, "stopTime": 1.0})
    run = run_project(cfg, tmp_path / "runs")
    whole = read_rows(run, "values.csv")
    switches = json.loads(hycosim("report", str(run), "--json").stdout)["mode_switches"]
    assert [s["to"] for s in switches] == ["hold", "free"]
    # What a SIGKILL during a write leaves: every finished line, then part of one.
    for name in ("values.csv", "timing.csv"):
        text = (run / name).read_text()
        (run / name).write_text(text[:text.index("\n", len(text) // 2) + 6])
    (run / "events.jsonl").write_text((run / "events.jsonl").read_text() + '{"step": 71, "t": 0.7')
    kept = read_csv_rows(run / "values.csv")
    assert 40 < len(kept) < len(whole) and kept == whole[:len(kept)]
    m = json.loads((run / "meta.json").read_text())
    (run / "meta.json").write_text(json.dumps({**m, "status": "running", "steps": 0}))  # as the server left it
    res = hycosim("report", str(run), "--json")
    assert res.returncode == 0, res.stderr
    s = json.loads(res.stdout)
    assert s["mode_switches"] == switches and s["status"] == "running"
    assert s["steps"] == len(read_csv_rows(run / "timing.csv")) > 40
    png = tmp_path / "cut.png"
    res = hycosim("plot", str(run), "clock.y", "-o", str(png))
    assert res.returncode == 0 and png.stat().st_size > 10_000, res.stderr
    # Killed before its first flush: nothing to draw, and it says so.
    empty = tmp_path / "empty-run"
    empty.mkdir()
    (empty / "meta.json").write_text((run / "meta.json").read_text())
    (empty / "values.csv").write_text("")
    res = hycosim("plot", str(empty), "-o", str(tmp_path / "empty.png"))
    assert res.returncode == 2 and "values.csv: no macro step recorded (yet)" in res.stderr, res.stderr
    assert not (tmp_path / "empty.png").exists()
    # A malformed line that is not the last is no torn write: named, not skipped.
    lines = (run / "values.csv").read_text().splitlines(keepends=True)
    lines[3] = "3,0.03\n"
    (run / "values.csv").write_text("".join(lines))
    res = hycosim("plot", str(run), "clock.y", "-o", str(png))
    assert res.returncode == 2 and f"{run / 'values.csv'}: line 4 does not have one cell" in res.stderr


def test_a_hand_edited_run_directory_is_named_cell_by_cell_not_a_traceback(tmp_path):
    import shutil

    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}],
        events=[{"name": "hold", "when": "clock.y >= 0.3", "drives": "g", "until": "clock.y >= 0.6"}],
        cosim={"stepSize": 0.01, "stopTime": 0.5})
    run = run_project(cfg, tmp_path / "runs")

    def edited(name: str, edit) -> str:
        copy = tmp_path / f"edit-{name}-{len(list(tmp_path.glob('edit-*')))}"
        shutil.copytree(run, copy)
        (copy / name).write_text(edit((copy / name).read_text()))
        return str(copy)

    def refused(*args: str) -> str:
        res = hycosim(*args)
        assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
        return res.stderr

    def cell(text: str, line: int, column: str, value: str) -> str:
        lines = text.splitlines()
        header = lines[0].split(",")
        cells = lines[line - 1].split(",")
        cells[header.index(column)] = value
        lines[line - 1] = ",".join(cells)
        return "\n".join(lines) + "\n"

    bad_wait = edited("timing.csv", lambda t: cell(t, 5, "wait_s", "soon"))
    assert f"{bad_wait}/timing.csv: line 5, column wait_s: 'soon' is not a finite number" in refused("report", bad_wait)
    endless = edited("timing.csv", lambda t: cell(t, 7, "step", "inf"))
    assert "line 7, column step: 'inf' is not a finite number" in refused("report", endless, "--json")
    no_t = edited("values.csv", lambda t: t.replace("step,t,", "step,time,", 1))
    assert f"{no_t}/values.csv: no column t in its header" in refused("plot", no_t)
    listed = edited("meta.json", lambda t: "[1, 2]")
    assert "not a run's metadata (a JSON object is expected, it holds a list)" in refused("report", listed)
    deep = edited("meta.json", lambda t: "[" * 5000)  # Python's JSON decoder recurses per level
    assert f"{deep}/meta.json: unreadable (nested too deeply)" in refused("report", deep)
    deep_events = edited("events.jsonl", lambda t: "{\"t\": " * 5000 + "\n" + t)
    assert "events.jsonl: line 1 is not JSON (nested too deeply to read)" in refused("plot", deep_events)
    typed = edited("meta.json", lambda t: json.dumps({**json.loads(t), "steps": "many"}))
    assert "not a run's metadata (steps: Input should be a valid integer" in refused("report", typed)
    undated = edited("events.jsonl", lambda t: t.replace('"t": ', '"time": ', 1))
    assert "events.jsonl: record 1 is not a mode switch (t: Field required)" in refused("plot", undated)
    assert "record 1 is not a mode switch" in refused("report", undated)
    worded = edited("values.csv", lambda t: cell(t, 12, "clock.y", "high"))
    assert "values.csv: clock.y is not a number at step 10 ('high')" in refused("plot", worded, "clock.y")
    # the other columns still plot, and the untouched run reports as before
    res = hycosim("plot", worded, "g.y", "-o", str(tmp_path / "g.png"))
    assert res.returncode == 0 and (tmp_path / "g.png").stat().st_size > 10_000, res.stderr
    assert json.loads(hycosim("report", str(run), "--json").stdout)["steps"] == 51


def test_a_long_run_is_read_back_in_one_pass(tmp_path):
    """A run of 200,000 recorded steps (the files as the recorder writes them, made here):
    the report's figures are those of the whole file, and the plot thins each line to its
    extremes per pixel bucket without losing a peak."""
    from array import array

    from hycosim.master.report import PLOT_BUCKETS, envelope, plot_run, summarise

    run = tmp_path / "long"
    run.mkdir()
    n = 200_000
    (run / "meta.json").write_text(json.dumps({"status": "completed", "steps": n}))
    waits = [((k * 7919) % 1000) * 1e-6 for k in range(n)]
    waits[123_456] = 0.5  # the slowest step, held by b
    with open(run / "timing.csv", "w") as f:
        f.write("step,t,wait_s,holder,lateness_s,arrival_s:a,arrival_s:b\n")
        for k, w in enumerate(waits):
            f.write(f"{k},{k * 0.001!r},{w:.9f},{'b' if k == 123_456 else 'a'},,{w:.9f},{w / 2:.9f}\n")
    with open(run / "values.csv", "w") as f:
        f.write("step,t,mode,a.y,b.y\n")
        for k in range(n):
            f.write(f"{k},{k * 0.001!r},free,{math.sin(k / 5000)!r},{3.0 if k == 77_777 else 0.0}\n")
    s = summarise(run)
    assert s.steps == n and s.holder_steps == {"a": n - 2, "b": 1}
    assert s.slowest_steps[0] == {"step": 123_456, "t": 123.456, "wait_ms": 500.0, "holder": "b"}
    assert [r["wait_ms"] for r in s.slowest_steps[1:]] == pytest.approx([0.999] * 4)  # ties: the earliest first
    assert [r["step"] for r in s.slowest_steps[1:]] == [k for k in range(1, n) if (k * 7919) % 1000 == 999][:4]
    assert s.mean_arrival_ms["a"] == pytest.approx(1000 * sum(waits[1:]) / (n - 1))
    t = array("d", (k * 0.001 for k in range(n)))
    spike = array("d", (3.0 if k == 77_777 else 0.0 for k in range(n)))
    tt, yy = envelope(t, spike)
    assert len(tt) <= 2 * PLOT_BUCKETS and 3.0 in yy and list(tt) == sorted(tt)
    gap = array("d", (math.nan if 1000 <= k < 5000 else 1.0 for k in range(n)))
    assert any(math.isnan(v) for v in envelope(t, gap)[1])  # a gap stays a gap
    short = array("d", [1.0, 2.0])
    assert list(envelope(array("d", [0.0, 1.0]), short)[1]) == [1.0, 2.0]
    png = plot_run(run, ["a.y", "b.y"], tmp_path / "long.png")
    assert png.stat().st_size > 10_000


def test_runs_started_in_the_same_second_get_folders_of_their_own(tmp_path):
    """Two runs of one project started together (trials, CI jobs) each get their own folder."""
    from concurrent.futures import ThreadPoolExecutor

    from hycosim.core.folders import run_dir_for

    with ThreadPoolExecutor(8) as pool:
        dirs = list(pool.map(lambda _: run_dir_for(tmp_path / "runs", "p"), range(24)))
    assert len(set(dirs)) == 24 and all(d.is_dir() for d in dirs)
    assert sorted(d.name for d in (tmp_path / "runs").iterdir()) == sorted(d.name for d in dirs)


_CELLS = st.sampled_from(["", "x", "nan", "inf", "-inf", "-1", "0", "1e400", "3", "0.5", "a,b", "\"", "2.0e-3"])


@st.composite
def _timing_files(draw) -> str:
    """A timing.csv as the recorder writes it (with takes), then some cells, lines or the header broken."""
    header = ["step", "t", "wait_s", "holder", "lateness_s", "arrival_s:a", "takes"]
    rows = [[str(k), repr(k * 0.01), "0.0001", "a", "", "0.0002", "1"] for k in range(draw(st.integers(0, 5)))]
    for _ in range(draw(st.integers(0, 4))):
        how = draw(st.sampled_from(["cell", "cell", "short", "long", "header"]))
        if how == "header":
            header[draw(st.integers(0, len(header) - 1))] = draw(st.sampled_from(["", "step", "t", "x"]))
        elif rows:
            row = rows[draw(st.integers(0, len(rows) - 1))]
            if not row:
                row.append(draw(_CELLS))
            elif how == "cell":
                row[draw(st.integers(0, len(row) - 1))] = draw(_CELLS)
            elif how == "short":
                del row[draw(st.integers(0, len(row) - 1)):]
            else:
                row.append(draw(_CELLS))
    return "\n".join(",".join(r) for r in [header, *rows]) + "\n"


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(timing=_timing_files(), meta_text=st.sampled_from(
    ['{"status": "completed", "steps": 3, "step_control": "steps of 0.001 to 0.1 s", "iteration": "up to 5 takes"}',
     '{"status": "running"}', '[]', '{"steps": "many"}', 'not json', "[" * 3000 + "]" * 3000]))
def test_a_run_directory_read_back_is_figures_or_a_named_error(tmp_path, timing, meta_text):
    """A run directory is a user's to edit: report, plot's step panels and the columns read it
    back, or say which file is wrong; never a traceback."""
    from hycosim.master.report import RunDirError, read_columns, read_steps, summarise

    run = tmp_path / "run"
    run.mkdir(exist_ok=True)
    (run / "meta.json").write_text(meta_text)
    (run / "timing.csv").write_text(timing)
    (run / "values.csv").write_text(timing.replace("holder", "mode"))
    for read in (summarise, read_steps, lambda r: read_columns(r, [])):
        try:
            got = read(run)
        except RunDirError as exc:
            assert str(run) in str(exc)
            continue
        if isinstance(got, dict) and "h" in got:  # read_steps: one length and one count per step
            assert len(got["t"]) == len(got["h"]) == len(got["takes"])
