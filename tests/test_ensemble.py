"""Sweeps: many runs of one project, its parameters varied, on Dask workers (a 2-worker
LocalCluster, and a scheduler and worker started as processes of their own, as a user attaches
a cluster). Each run's values are those of the same variant run alone; a run that fails or
outlasts its time is a row saying so and the others go on; --resume skips what completed;
what is malformed is named before any run starts (exit 2)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import hycosim
from tests.helpers import hycosim as cli, spawn

pq = pytest.importorskip("pyarrow.parquet", reason="pyarrow is in the [ensemble] extra")
pytest.importorskip("dask.distributed", reason="dask is in the [ensemble] extra")

def _failing_project(path: Path, co_simulation: dict) -> Path:
    """One node, tests.nodes.FailsAt (y = t; raises once t passes its ``at`` parameter)."""
    path.write_text(json.dumps({
        "projectName": path.stem, "nodeNum": 1, "linkNum": 0, "linkLists": [],
        "nodeLists": [{"nodeName": "f", "UID": 1, "model": "tests.nodes:FailsAt", "output": ["y"]}],
        "coSimulation": co_simulation}))
    return path


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    if shutil.which("gcc") is None:
        pytest.skip("needs gcc")
    from benchmarks._small_fmus import write_package

    project, _ = write_package(tmp_path_factory.mktemp("small"), 100)
    return project


def _rows(out: Path) -> list[dict]:
    return sorted(pq.read_table(out / "runs.parquet").to_pylist(), key=lambda r: r["run"])


def test_a_grid_on_two_local_workers_records_what_each_variant_records_alone(small, tmp_path):
    out = tmp_path / "sweep"
    res = cli("sweep", str(small), "--set", "dahlquist.k=0.5,2", "--set", "vdp.mu=1,3", "--workers", "2",
              "--metric", "dahlquist.x:final", "--metric", "vdp.x0:min", "--values", "-o", str(out), timeout=300)
    assert res.returncode == 0, res.stderr
    rows = _rows(out)
    assert [(r["dahlquist.k"], r["vdp.mu"]) for r in rows] == [(0.5, 1), (0.5, 3), (2, 1), (2, 3)]
    assert all(r["outcome"] == "completed" and r["steps_per_s"] > 0 for r in rows)
    doc = json.loads(small.read_text())
    for r in rows[1:3]:  # two variants, each run alone with hycosim run
        variant = json.loads(json.dumps(doc))
        for node in variant["nodeLists"]:
            node.setdefault("parameters", {}).update(
                {"dahlquist": {"k": r["dahlquist.k"]}, "vdp": {"mu": r["vdp.mu"]}}.get(node["nodeName"], {}))
        cfg = small.parent / f"variant-{r['run']}.json"
        cfg.write_text(json.dumps(variant))
        alone = tmp_path / f"alone-{r['run']}"
        done = cli("run", str(cfg), "--runs-dir", str(alone), "--no-progress", "--in-process")
        assert done.returncode == 0, done.stderr
        ran = next(alone.iterdir()) / "values.csv"
        assert (Path(r["run_dir"]) / "values.csv").read_bytes() == ran.read_bytes(), r["run"]
        last = ran.read_text().splitlines()
        header, final = last[0].split(","), last[-1].split(",")
        assert r["dahlquist.x:final"] == float(final[header.index("dahlquist.x")])
    values = pq.read_table(out / "values.parquet")
    assert sorted(set(values.column("run").to_pylist())) == [0, 1, 2, 3] and values.num_rows == 4 * 101


def test_a_failing_run_is_a_row_and_the_others_go_on_and_resume_skips_what_completed(tmp_path):
    project = _failing_project(tmp_path / "fails.json", {"stepSize": 0.01, "stopTime": 0.5})
    out = tmp_path / "sweep"
    res = cli("sweep", str(project), "--set", "f.at=0.05,5,0.2", "--workers", "2", "-o", str(out), timeout=300)
    assert res.returncode == 1, res.stderr  # a run did not complete
    rows = _rows(out)
    assert [r["outcome"] for r in rows] == ["failed", "completed", "failed"]
    assert "divided by zero" in rows[0]["message"] and "divided by zero" in rows[2]["message"]
    assert "run 0: failed" in res.stdout
    completed_dir = rows[1]["run_dir"]
    # Resumed with the failing values changed: only the runs not completed run again.
    res = cli("sweep", str(project), "--set", "f.at=5,5,5", "--resume", str(out), timeout=300)
    assert res.returncode == 0, res.stderr
    again = _rows(out)
    assert [r["outcome"] for r in again] == ["completed"] * 3 and again[1]["run_dir"] == completed_dir
    # A run past its time is stopped and recorded as timeout.
    slow = tmp_path / "slow.json"
    doc = json.loads(project.read_text())
    doc["coSimulation"] = {"stepSize": 0.01, "stopTime": 1e6, "realTime": True}  # paced: far past 1.5 s
    slow.write_text(json.dumps(doc))
    res = cli("sweep", str(slow), "--set", "f.at=1e9", "--timeout", "1.5", "-o", str(tmp_path / "slow"), timeout=300)
    [row] = _rows(tmp_path / "slow")
    assert res.returncode == 1 and row["outcome"] == "timeout" and "still running after 1.5 s" in row["message"]


def test_ctrl_c_cancels_the_sweep_and_keeps_the_runs_that_ended(tmp_path):
    project = _failing_project(tmp_path / "paced.json",
                               {"stepSize": 0.05, "stopTime": 1.0, "realTime": True})  # a second a run
    out = tmp_path / "out"
    proc = spawn("sweep", str(project), "--set", "f.at=1e3,1e4,1e5,1e6,1e7,1e8", "--workers", "1", "-o", str(out),
                 start_new_session=True)
    deadline = time.monotonic() + 120
    while not (out / "runs.parquet").exists():
        assert time.monotonic() < deadline and proc.poll() is None, proc.communicate()
        time.sleep(0.1)
    os.killpg(proc.pid, signal.SIGINT)  # a terminal's Ctrl-C: the whole group (the workers have left it)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130 and "the runs that ended are in" in stderr, stderr
    assert "Traceback" not in stderr, stderr
    rows = _rows(out)
    assert 1 <= len(rows) < 6 and all(r["outcome"] == "completed" for r in rows)


def test_a_sweep_from_python_on_a_scheduler_and_worker_started_apart(small, tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    dask = Path(sys.executable).with_name("dask")
    address = f"tcp://127.0.0.1:{port}"
    scheduler = subprocess.Popen([str(dask), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                                  "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = subprocess.Popen([str(dask), "worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                with socket.create_connection(("127.0.0.1", port), timeout=1):
                    break
            except OSError:
                assert time.monotonic() < deadline, "the scheduler did not listen"
                time.sleep(0.2)
        table = hycosim.sweep(small, {"dahlquist.k": "uniform(0.1,3)"}, samples=3, seed=7, scheduler=address,
                              metrics=["dahlquist.x:final"], out=tmp_path / "out")
        rows = table.to_pylist() if hasattr(table, "to_pylist") else table.to_dict("records")
        assert len(rows) == 3 and all(r["outcome"] == "completed" for r in rows)
        ks = [r["dahlquist.k"] for r in rows]
        assert all(0.1 <= k <= 3 for k in ks) and len(set(ks)) == 3
        # Faster decay, lower final value: the parameter reached each run.
        order = sorted(rows, key=lambda r: r["dahlquist.k"])
        assert order[0]["dahlquist.x:final"] > order[1]["dahlquist.x:final"] > order[2]["dahlquist.x:final"]
        again = hycosim.sweep(small, {"dahlquist.k": "uniform(0.1,3)"}, samples=3, seed=7, scheduler=address,
                              out=tmp_path / "again")
        same = again.to_pylist() if hasattr(again, "to_pylist") else again.to_dict("records")
        assert [r["dahlquist.k"] for r in same] == ks  # the seed draws the same values
    finally:
        for proc in (worker, scheduler):
            proc.terminate()
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()


@pytest.mark.parametrize("args, says", [
    (["--set", "dahlquist.nope=1,2"], "parameter 'nope' is not a variable of Dahlquist.fmu"),
    (["--set", "ghost.k=1"], "the project has no node 'ghost'"),
    (["--set", "dahlquist.k="], "an empty value"),
    (["--set", "dahlquist.k=uniform(1)", "--samples", "2"], "uniform takes two numbers"),
    (["--set", "dahlquist.k=normal(0,-1)", "--samples", "2"], "normal(mean,sd) needs sd > 0"),
    (["--set", "dahlquist.k=uniform(0,1)"], "a distribution needs --samples N"),
    (["--set", "dahlquist.k=1,2", "--set", "vdp.mu=1,2,3", "--zip"], "--zip over sets of different lengths"),
    (["--set", "dahlquist.k=1", "--metric", "dahlquist.nope:final"], "the project has no port dahlquist.nope"),
    (["--set", "dahlquist.k=1", "--metric", "dahlquist.x:median"], "write node.port:final"),
    (["--set", "dahlquist.k=abc"], "'abc'"),
])
def test_what_is_malformed_is_named_before_any_run_starts(small, tmp_path, args, says):
    out = tmp_path / "out"
    res = cli("sweep", str(small), *args, "-o", str(out))
    assert res.returncode == 2 and says in res.stderr, res.stderr
    assert "Traceback" not in res.stderr and not (out / "runs.parquet").exists()


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture], max_examples=60)
@given(rows=st.lists(st.dictionaries(st.sampled_from(["run", "outcome", "run_dir", "x"]),
                                     st.none() | st.integers(-5, 5) | st.sampled_from(["completed", "failed", ""])
                                     | st.floats(allow_nan=True)), max_size=6),
       damaged=st.booleans())
def test_the_table_resumed_from_gives_completed_runs_by_number_or_one_named_error(tmp_path, rows, damaged):
    import pyarrow as pa

    from hycosim.ensemble.sweep import RUNS_TABLE, SweepError, _finished

    out = tmp_path / "t"
    out.mkdir(exist_ok=True)
    if damaged:
        (out / RUNS_TABLE).write_bytes(b"PAR1" + json.dumps(rows).encode())
    else:
        try:
            table = pa.Table.from_pylist(rows)
        except (pa.ArrowInvalid, pa.ArrowTypeError):
            return  # no table of these rows can be written
        pq.write_table(table, out / RUNS_TABLE)
    try:
        kept = _finished(out)
    except SweepError as exc:
        assert RUNS_TABLE in str(exc)
        return
    assert all(type(r["run"]) is int and r["outcome"] == "completed" for r in kept)


# What a --set holds, piece by piece: mostly the right shape, with each part now and then wrong.
_NODES = st.sampled_from(["dahlquist", "vdp", "f", "a-b_2", "", "1x", "no de", "é"])
_NAMES = st.sampled_from(["k", "mu", "at", "x.y", "", "a b", "=", "k[0]"])
_VALUES = st.sampled_from(["1", "-2.5e3", "1e400", "NaN", "true", "null", '"txt"', '"', "abc", "", " ", "[1]",
                           "{}", "[" * 3000 + "]" * 3000, "1" * 5000, "inf", "0x10"])
_DRAWS = st.sampled_from(["uniform", "normal", "choice", "lognormal", "uniform "])


@st.composite
def _setting_texts(draw) -> str:
    value = st.lists(_VALUES, min_size=0, max_size=4).map(",".join)
    if draw(st.booleans()):
        value = st.tuples(_DRAWS, value, st.sampled_from([")", "", "))"])).map(lambda p: f"{p[0]}({p[1]}{p[2]}")
    separator = draw(st.sampled_from(["=", "=", "=", "", "==", " = "]))
    return f"{draw(_NODES)}.{draw(_NAMES)}{separator}{draw(value)}"


@given(texts=st.lists(_setting_texts() | st.text(max_size=20), max_size=4), zipped=st.booleans(),
       samples=st.none() | st.integers(-1, 3), seed=st.integers())
def test_sets_give_their_runs_or_one_sweep_error(texts, zipped, samples, seed):
    """Whatever a --set holds (or a Python caller's parameters turned into one), parsing it and
    laying out the runs gives the runs or one SweepError naming the fault: no other exception."""
    from hycosim.ensemble.variants import SweepError, parse_setting, variants

    try:
        runs = variants([parse_setting(t) for t in texts], zipped=zipped, samples=samples, seed=seed)
    except SweepError as exc:
        assert str(exc)
        return
    assert runs and all(set(r) == set(runs[0]) and len(r) == len(texts) for r in runs)
    assert samples is None or len(runs) == samples


_CELLS = st.sampled_from(["1.5", "nan", "x", "", '"', "1e999", "a" * 200_000, "\u00e9", ",", "\r\n"])


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture], max_examples=60)
@given(rows=st.lists(st.lists(_CELLS, max_size=4), max_size=4), header=st.sampled_from(["t,f.y", "f.y", "", "t"]),
       meta=st.sampled_from([b"", b"[]", b"{}", b'{"steps_per_s": "fast"}', b'{"steps_per_s": 1e999}',
                             b'{"steps_per_s": 250.0}', b"[" * 5000, b"\xff\xfe"]),
       binary=st.binary(max_size=64) | st.none())
def test_a_run_directorys_values_and_meta_give_metrics_and_a_rate_whatever_they_hold(tmp_path, rows, header,
                                                                                      meta, binary):
    """A run's row reads its run directory, which a user may edit or break: every metric is a
    number (NaN where nothing is read) and the rate a number, never an exception."""
    import math

    from hycosim.ensemble.runs import _rate, metrics_of, parse_metric

    run = tmp_path / "run"
    run.mkdir(exist_ok=True)
    values = binary if binary is not None else "\n".join([header, *(",".join(r) for r in rows)]).encode()
    (run / "values.csv").write_bytes(values)
    (run / "meta.json").write_bytes(meta)
    got = metrics_of(run, [parse_metric("f.y:final"), parse_metric("f.y:mean")])
    assert set(got) == {"f.y:final", "f.y:mean"} and all(type(v) is float for v in got.values())
    rate = _rate(run, 100, 2.0)
    assert type(rate) is float and (rate == 250.0 if meta == b'{"steps_per_s": 250.0}' else rate == 50.0)
    assert not math.isnan(rate)
