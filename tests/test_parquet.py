"""Recording as Parquet: the CSV's tables, typed, in parts; rolled back by deleting parts;
read by report, plot, replay and the dashboard as the CSV is."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from hycosim.core.config import load_project
from hycosim.core.run_files import RunFileError, iter_csv_rows, table_lines
from hycosim.master import report
from hycosim.master.parquet_tables import ParquetTables, parts, recorded_rows, table_dir
from tests.helpers import hycosim, kill_process, meta, reap, run_project, spawn, wait_for, write_project


def _typed_project(tmp_path: Path, name: str = "typed", **cosim) -> Path:
    nodes = [
        {"nodeName": "typed", "UID": 1, "model": "tests.nodes:Typed", "input": ["u"],
         "output": [{"name": "i", "type": "Integer"}, {"name": "b", "type": "Boolean"}, "r",
                    {"name": "s", "type": "String"}]},
        {"nodeName": "bytes", "UID": 2, "model": "tests.nodes:Bytes",
         "output": [{"name": "label", "type": "String"}, {"name": "blob", "type": "Binary"}, "w"]},
        {"nodeName": "vec", "UID": 3, "model": "tests.nodes:Vector", "output": [{"name": "v", "shape": [2]}, "total"]},
        {"nodeName": "g", "UID": 4, "model": "gain", "parameters": {"k": 2.0}, "input": ["u"], "output": ["y"]},
    ]
    links = [{"from": "bytes.w", "to": "g.u"}, {"from": "g.y", "to": "typed.u"}]
    return write_project(tmp_path / f"{name}.json", nodes, links, name=name,
                         cosim={"stepSize": 0.1, "stopTime": 3.0, **cosim})


def _csv_cells(run: Path, name: str) -> list[list[str]]:
    lines = (run / name).read_text().splitlines()
    return [line.split(",") for line in lines]


@pytest.mark.parametrize("mode", ["--in-process", "--processes"])
def test_a_parquet_run_records_the_csvs_columns_typed_with_the_same_values(tmp_path, mode):
    cfg = _typed_project(tmp_path)
    csv_run = run_project(cfg, tmp_path / "csv") if mode == "--processes" else None
    res = hycosim("run", str(cfg), mode, "--no-progress", "--runs-dir", str(tmp_path / "csv2"))
    assert res.returncode == 0, res.stderr
    csv_run = csv_run or next((tmp_path / "csv2").iterdir())
    res = hycosim("run", str(cfg), mode, "--no-progress", "--record", "parquet", "--runs-dir", str(tmp_path / "pq"))
    assert res.returncode == 0, res.stderr
    run = next((tmp_path / "pq").iterdir())
    assert not (run / "values.csv").exists() and meta(run)["recording"] == "parquet"
    table = pq.read_table(run / "values.parquet")
    csv_rows = _csv_cells(csv_run, "values.csv")
    assert table.column_names == csv_rows[0]
    types = dict(zip(table.column_names, table.schema.types))
    assert types["typed.i"] == pa.int64() and types["typed.b"] == pa.bool_() and types["typed.r"] == pa.float64()
    assert types["typed.s"] == pa.string() and types["bytes.blob"] == pa.binary() and types["step"] == pa.int64()
    assert types["vec.v[0]"] == pa.float64() and types["vec.v[1]"] == pa.float64()
    assert table.num_rows == len(csv_rows) - 1 == 31
    for column, kind in types.items():
        recorded = table.column(column).to_pylist()
        text = [row[csv_rows[0].index(column)] for row in csv_rows[1:]]
        if kind == pa.bool_():
            assert [str(int(v)) for v in recorded] == text, column
        elif kind == pa.binary():
            assert [v.hex() for v in recorded] == text, column
        elif kind == pa.float64():
            assert [repr(v) for v in recorded] == text, column  # the same doubles, bit for bit
        else:
            assert [str(v) for v in recorded] == text, column
    assert {f.name for f in run.iterdir()} >= {"values.parquet", "timing.parquet", "events.jsonl", "meta.json"}
    timing = pq.read_table(run / "timing.parquet")
    assert timing.column_names == _csv_cells(csv_run, "timing.csv")[0] and timing.num_rows == 31
    assert timing.schema.field("wait_s").type == pa.float64() and timing.schema.field("step").type == pa.int64()
    # The readers take either: the report's figures, a plot's columns, the rows as the CSV's text.
    a, b = report.summarise(csv_run), report.summarise(run)
    assert (a.steps, a.node_steps, a.status) == (b.steps, b.node_steps, b.status)  # who held the barrier is timing
    ports = ["typed.r", "typed.i", "vec.v[1]", "g.y"]
    assert report.read_columns(run, ports) == report.read_columns(csv_run, ports)
    assert list(table_lines(run / "values.csv")) == csv_rows


def test_a_recorded_parquet_run_is_played_back_and_shown_as_the_csv_one(tmp_path):
    cfg = _typed_project(tmp_path)
    source = run_project(cfg, tmp_path / "csv")
    res = hycosim("run", str(cfg), "--in-process", "--no-progress", "--record", "parquet", "--runs-dir",
                  str(tmp_path / "pq"))
    assert res.returncode == 0, res.stderr
    played_from = next((tmp_path / "pq").iterdir())
    doc = json.loads(cfg.read_text())
    doc["nodeLists"][0]["replay"] = str(played_from)  # the typed node's outputs, from the Parquet run
    (tmp_path / "replayed.json").write_text(json.dumps(doc))
    replayed = run_project(tmp_path / "replayed.json", tmp_path / "replayed")
    assert (replayed / "values.csv").read_text() == (source / "values.csv").read_text()

    from hycosim.dashboard.finished import FinishedRun, _column

    shown, csv_shown = FinishedRun(played_from), FinishedRun(source)
    try:
        assert shown._columns == csv_shown._columns and shown._end == csv_shown._end
        assert shown._end["t"] == pytest.approx(3.0) and shown._end["values"]["typed.i"] == 83.0
        assert _column(played_from, "typed.r") == _column(source, "typed.r")
    finally:
        shown._pool.shutdown()
        csv_shown._pool.shutdown()


def _slow_project(tmp_path: Path, name: str) -> Path:
    nodes = [{"nodeName": "pend", "UID": 1, "model": "pendulum", "parameters": {"theta0": 0.5}, "input": ["theta_in"],
              "output": ["theta", "omega"]},
             {"nodeName": "g1", "UID": 2, "model": "gain", "parameters": {"k": 2.0}, "input": ["u"], "output": ["y"]},
             {"nodeName": "g2", "UID": 3, "model": "gain", "parameters": {"k": 0.5, "work_s": 0.004},
              "input": ["u"], "output": ["y"]}]
    links = [{"from": "pend.theta", "to": "g1.u"}, {"from": "g1.y", "to": "g2.u"}, {"from": "g2.y", "to": "pend.theta_in"}]
    return write_project(tmp_path / f"{name}.json", nodes, links, name=name,
                         cosim={"stepSize": 0.01, "stopTime": 6.0, "checkpointEvery": 0.5, "attachTimeout": 20.0},
                         recording={"format": "parquet"})


@pytest.mark.parametrize("kill", ["node g2", "server"])
def test_a_parquet_run_taken_back_to_a_checkpoint_records_what_a_run_never_stopped_does(tmp_path, kill):
    cfg = _slow_project(tmp_path, "slow")
    reference = run_project(cfg, tmp_path / "reference")
    runs = tmp_path / "runs"
    proc = spawn("run", str(cfg), "--runs-dir", str(runs), "--no-progress", "--restarts", "2")
    try:
        wait_for(lambda: runs.exists() and any(runs.iterdir()) and table_dir(next(runs.iterdir()), "values.csv")
                 .is_dir() and recorded_rows(next(runs.iterdir())) >= 250, 60, "250 rows")
        kill_process(f"hycosim {kill} {cfg}")
        _, err = proc.communicate(timeout=120)
    finally:
        reap(proc)
    run = next(runs.iterdir())
    if kill == "server":
        assert proc.returncode == 3 and "--resume" in err, err
        res = hycosim("run", str(cfg), "--resume", str(run), "--no-progress", timeout=120)
        assert res.returncode == 0, res.stderr
    else:
        assert proc.returncode == 0, err
        assert [r["node"] for r in meta(run)["recoveries"]] == ["g2"]
    assert pq.read_table(run / "values.parquet").equals(pq.read_table(reference / "values.parquet"))
    assert meta(run)["status"] == "completed" and meta(run)["recording"] == "parquet"


def test_going_back_to_a_checkpoint_deletes_the_parts_after_it_and_rewrites_none(tmp_path):
    loaded = load_project(_slow_project(tmp_path, "unit"))
    tables = ParquetTables(tmp_path, loaded.project, False, {}, ["step", "t", "wait_s", "holder", "lateness_s"])
    tables.csv_row("timing.csv", ["step", "t", "wait_s", "holder", "lateness_s"])  # a header: passed over
    row = lambda k: [k, k * 0.01, "free", 0.1 * k, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0]  # noqa: E731

    for k in range(10):
        tables.values(row(k))
        tables.timing((k, k * 0.01, 0.001, "g2", ""))
    assert tables.positions() == {"values.csv": 10, "timing.csv": 10}  # a checkpoint: a part boundary
    first = parts(tmp_path / "values.parquet")
    stamp = [(p, p.stat().st_mtime_ns) for _, p in first]
    for k in range(10, 25):
        tables.values(row(k))
        tables.timing((k, k * 0.01, 0.001, "g2", "0.000100"))
    tables.positions()
    for k in range(25, 30):
        tables.values(row(k))  # waiting, not in a part yet
    tables.cut({"values.csv": 10, "timing.csv": 10})
    assert parts(tmp_path / "values.parquet") == first and all(p.stat().st_mtime_ns == m for p, m in stamp)
    for k in range(10, 12):
        tables.values(row(k))
        tables.timing((k, k * 0.01, 0.002, "g1", ""))
    assert tables.close() == []
    values = pq.read_table(tmp_path / "values.parquet")
    assert values.column("step").to_pylist() == list(range(12))
    timing = pq.read_table(tmp_path / "timing.parquet")
    assert timing.column("holder").to_pylist() == ["g2"] * 10 + ["g1"] * 2
    assert timing.column("lateness_s").to_pylist() == [None] * 12 and recorded_rows(tmp_path) == 12


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=300) | st.sampled_from([b"PAR1", b"PAR1\x00\x00\x00\x00PAR1"]), st.booleans())
def test_a_values_table_of_any_bytes_is_read_whole_or_refused_naming_the_part(tmp_path, data, before):
    """A damaged or forged part beside a good one: every reader gets rows or a RunFileError
    naming the part, never another exception."""
    run = tmp_path / "run"
    folder = run / "values.parquet"
    folder.mkdir(parents=True, exist_ok=True)
    for old in folder.iterdir():
        old.unlink()
    good = pa.table({"step": pa.array([0, 1], pa.int64()), "t": pa.array([0.0, 0.1]), "x.y": [1.5, math.inf]})
    pq.write_table(good, folder / f"part-{(5 if before else 0):012d}.parquet")
    (folder / f"part-{(0 if before else 5):012d}.parquet").write_bytes(data)
    try:
        rows = list(iter_csv_rows(run / "values.csv", lambda c: c in ("step", "t"), required=("step", "t")))
    except RunFileError as exc:
        assert "part-" in str(exc) or "values.parquet" in str(exc)
    else:
        assert all(set(r) >= {"step", "t"} for r in rows)
