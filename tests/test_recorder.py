"""The recorder's rows are the text Python's csv.writer makes of their cells, whichever way it
writes them: joined where no cell can need a quote, through csv.writer where a String port
may hold any text; and a timing row in one format is the row of formatted cells. The same
text whether the recorder formats the rows itself or a process of its own does (``apart``,
as in a run in one process)."""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hycosim.core.config import load_project
from hycosim.master.recorder import Recorder
from tests.helpers import write_project

_FIXTURES = settings(suppress_health_check=[HealthCheck.function_scoped_fixture])

_REAL = st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from([0.0, -0.0, 5e-324, 1e16, 1e-5, 0.1])
_INTEGER = st.integers(-2**63, 2**64)
_TEXT = st.text(alphabet=st.sampled_from('ab ,"\r\n;x\'é'), max_size=8)


def _project(tmp: Path, strings: bool) -> Path:
    outputs = [{"name": "r", "type": "Real"}, {"name": "i", "type": "Integer"}, {"name": "b", "type": "Boolean"},
               {"name": "v", "type": "Real", "shape": [2]}]
    if strings:
        outputs.append({"name": "s", "type": "String"})
    # Only the ports matter to the recorder: no model is run here.
    nodes = [{"nodeName": "a", "UID": 1, "model": "tests.nodes:Vector", "output": outputs},
             {"nodeName": "b-2", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]}]
    return write_project(tmp / f"p{int(strings)}.json", nodes, [{"from": "a.r", "to": "b-2.u"}],
                         cosim={"stepSize": 0.1, "stopTime": 1.0})


@pytest.fixture(scope="module", params=[False, True], ids=["numbers", "with a String port"])
def loaded(request, tmp_path_factory):
    return load_project(_project(tmp_path_factory.mktemp("rec"), request.param))


def _a_cells(values: list) -> list:
    r, i, b, v, *s = values
    return [r, i, int(b), *v, *s]


def _expected(rows: list[list]) -> str:
    out = io.StringIO()
    writer = csv.writer(out)
    for row in rows:
        writer.writerow(row)
    return out.getvalue()


# Rows written apart start their writing process anew in each example: fewer examples hold that
# hand-off, the cells' formatting (the same code) has its full count written here.
_APART = settings(_FIXTURES, max_examples=30)


@_FIXTURES
@given(data=st.data(), count=st.integers(1, 4))
def test_values_rows_are_what_csv_writer_makes_of_their_cells(loaded, tmp_path_factory, data, count):
    _values_rows(loaded, False, tmp_path_factory, data, count)


@_APART
@given(data=st.data(), count=st.integers(1, 4))
def test_values_rows_written_apart_are_what_csv_writer_makes_of_their_cells(loaded, tmp_path_factory, data, count):
    _values_rows(loaded, True, tmp_path_factory, data, count)


def _values_rows(loaded, apart, tmp_path_factory, data, count) -> None:
    strings = any(p.name == "s" for p in loaded.project.node("a").output)
    run_dir = tmp_path_factory.mktemp("run")
    recorder = Recorder(run_dir, loaded, {}, rows_apart=apart)
    want = []
    for step in range(count):
        a = [data.draw(_REAL), data.draw(_INTEGER), data.draw(st.booleans()), data.draw(st.lists(_REAL, min_size=2,
                                                                                               max_size=2))]
        if strings:
            a.append(data.draw(_TEXT))
        y, u, t = data.draw(_REAL), data.draw(_REAL), data.draw(_REAL)
        mode = data.draw(st.sampled_from(["free", "grasp", "hold_2"]))
        recorder.row(step, t, mode, {"a": a, "b-2": [y]}, {"a": [], "b-2": [u]})
        want.append([step, repr(t), mode, *_a_cells(a), y, u])
    recorder.close("completed")
    text = (run_dir / "values.csv").read_bytes().decode()
    header, _, rows = text.partition("\r\n")
    assert rows == _expected(want)
    assert header.split(",")[:4] == ["step", "t", "mode", "a.r"]


_SECONDS = st.floats(0.0, 1e4, allow_nan=False)


@_FIXTURES
@given(data=st.data(), count=st.integers(1, 4))
def test_timing_rows_are_their_formatted_cells_whichever_nodes_arrived(loaded, tmp_path_factory, data, count):
    _timing_rows(loaded, False, tmp_path_factory, data, count)


@_APART
@given(data=st.data(), count=st.integers(1, 4))
def test_timing_rows_written_apart_are_their_formatted_cells(loaded, tmp_path_factory, data, count):
    _timing_rows(loaded, True, tmp_path_factory, data, count)


def _timing_rows(loaded, apart, tmp_path_factory, data, count) -> None:
    run_dir = tmp_path_factory.mktemp("run")
    recorder = Recorder(run_dir, loaded, {}, rows_apart=apart)
    want = []
    for step in range(count):
        # "src" steps in no release of its own (a played source is gathered too): no column of its own.
        arrived = data.draw(st.sets(st.sampled_from(["a", "b-2", "src"])))
        arrivals = {n: data.draw(_SECONDS) for n in sorted(arrived)}
        t, wait = data.draw(_REAL), data.draw(_SECONDS)
        lateness = data.draw(st.none() | _SECONDS)
        holder = data.draw(st.sampled_from(["", "a", "b-2"]))
        recorder.timing(step, t, wait, holder, lateness, arrivals, {})
        want.append([step, repr(t), f"{wait:.9f}", holder, "" if lateness is None else f"{lateness:.6f}",
                     *(f"{arrivals[n]:.9f}" if n in arrivals else "" for n in ("a", "b-2"))])
    recorder.close("completed")
    header, _, rows = (run_dir / "timing.csv").read_bytes().decode().partition("\r\n")
    assert header == "step,t,wait_s,holder,lateness_s,arrival_s:a,arrival_s:b-2"
    assert rows == _expected(want)


@pytest.mark.parametrize("apart", [False, True], ids=["here", "apart"])
def test_a_non_finite_time_or_value_is_written_as_python_writes_it(tmp_path, apart):
    loaded = load_project(_project(tmp_path, False))
    (tmp_path / "run").mkdir()
    recorder = Recorder(tmp_path / "run", loaded, {}, rows_apart=apart)
    recorder.row(0, math.inf, "free", {"a": [math.nan, 2**64, True, [-0.0, 1e16]], "b-2": [-math.inf]},
                 {"a": [], "b-2": [5e-324]})
    recorder.close("completed")
    assert (tmp_path / "run" / "values.csv").read_text().splitlines()[1] == "0,inf,free,nan,18446744073709551616,1," \
        "-0.0,1e+16,-inf,5e-324"


def test_the_recorder_goes_back_only_to_a_checkpoint_whose_positions_it_was_given(loaded, tmp_path):
    from hycosim.master.observers import RecordedPoint
    from hycosim.master.record_files import RecordError

    recorder = Recorder(tmp_path, loaded, {})
    point = RecordedPoint(loaded.project)
    a = [0.5, 1, True, [0.0, 1.0]] + (["x"] if any(p.name == "s" for p in loaded.project.node("a").output) else [])
    point.mode, point.outputs, point.inputs = "free", {"a": a, "b-2": [1.0]}, {"a": [], "b-2": [0.5]}
    point.arrivals = {"a": 0.001, "b-2": 0.002}
    for k in range(2):
        recorder.step_complete(k, 0.1 * k, point)
    at = recorder.positions(2)  # a checkpoint at point 2 is taken as the loop reaches it, before its row
    for k in range(2, 6):
        recorder.step_complete(k, 0.1 * k, point)
    with pytest.raises(RecordError, match="back to step 2: no checkpoint's positions"):
        recorder.state_restored(2, 0.2)
    recorder.going_back(2, at)
    recorder.state_restored(2, 0.2)
    recorder.run_ended("completed")
    rows = list(csv.reader(open(tmp_path / "values.csv", newline="")))[1:]
    timing = list(csv.reader(open(tmp_path / "timing.csv", newline="")))[1:]
    assert [r[0] for r in rows] == [r[0] for r in timing] == ["0", "1"]
    assert json.loads((tmp_path / "meta.json").read_text())["status"] == "completed"


_CELL = (st.floats() | st.floats(-1e-3, 1e-3) | st.floats(1e14, 1e18) | st.integers() | st.booleans()
         | st.binary(max_size=3) | st.sampled_from([0.0, -0.0, 1e16, 1e-4, 9.999999999999999e-05, 1e15 + 0.5]))


@given(st.integers(0, 2 ** 40), st.floats(0, 1e9), st.sampled_from(["free", "grasped"]), st.none() | st.text(max_size=5),
       st.lists(_CELL, max_size=12))
def test_a_values_row_is_the_text_csv_writer_gives_its_cells(step, t, mode, stepped, values):
    """joined_row writes the ports' values through msgspec where its text of them is Python's:
    every row, whatever its values (any float, integers beyond 64 bits, booleans, bytes),
    is the text csv.writer writes of its cells."""
    from hycosim.master.record_files import joined_row

    lead = [step, t, mode] + ([] if stepped is None else [stepped.replace(",", "").replace('"', "")])
    cells = [*lead, *values]
    text = io.StringIO()
    csv.writer(text).writerow(cells)
    if '"' in text.getvalue():
        return  # a cell csv.writer quotes: joined_row is never given one
    assert joined_row(cells, len(lead)) == text.getvalue()


_MODE = st.sampled_from(["free", "grasped", "null", "e", "n0"]) | st.from_regex(r"[A-Za-z_][A-Za-z0-9_\-]{0,6}", fullmatch=True)


# Cells whose text msgspec writes as Python does (the rows of a run like any): batches of them
# take the one call; any other cell among them sends the batch row by row.
def _plain(x: float) -> bool:
    return (x == 0 or abs(x) >= 1e-4) and "0.0000" not in repr(x)  # no exponent, nothing looking like one


_PLAIN_CELL = st.integers(-2 ** 63, 2 ** 63) | st.floats(-1e9, 1e9).filter(_plain)
_ROWS = st.lists(st.tuples(st.integers(0, 2 ** 40), st.floats(0, 1e9).filter(_plain),
                           st.sampled_from(["free", "grasped"]), st.lists(_PLAIN_CELL, max_size=8)), min_size=2, max_size=12)


@given(_ROWS | st.lists(st.tuples(st.integers(0, 2 ** 70), st.floats(0, 1e9) | st.floats(), _MODE,
                                  st.lists(_CELL | _PLAIN_CELL | _MODE | st.text("0123456789abcdef", max_size=6)
                                           | st.just("<40 bytes>"), max_size=8)), max_size=12))
def test_rows_joined_together_are_the_text_csv_writer_gives_them(rows):
    """joined_rows (a distributed server's rows at each flush, in one msgspec call) writes what
    csv.writer writes of each row, one after another: whatever the modes (any identifier, one
    that is also a value's text), the values (strings as the recorder makes of bytes, any float,
    integers beyond 64 bits) and the steps."""
    from hycosim.master.record_files import joined_rows

    taken, expected = [], []
    for step, t, mode, values in rows:
        text = io.StringIO()
        csv.writer(text).writerow([step, t, mode, *values])
        if '"' not in text.getvalue():  # a cell csv.writer quotes: the recorder never joins one
            taken.append([step, t, mode, *values])
            expected.append(text.getvalue())
    assert joined_rows(taken) == "".join(expected)
    assert joined_rows(taken, lead=4) == "".join(expected)  # lead 4 ("stepped" cells): row by row


@given(_ROWS)
def test_plain_rows_are_joined_in_one_call(rows):
    """A batch of plain rows (numbers, the run's modes) is written in one msgspec call, not row
    by row, and its text is csv.writer's."""
    from hycosim.master import record_files

    cells = [[step, t, mode, *values] for step, t, mode, values in rows]
    expected = "".join(record_files.joined_row(c) for c in cells)
    by_row = record_files.joined_row
    record_files.joined_row = None  # type: ignore[assignment]  # row by row would fail
    try:
        assert record_files.joined_rows(cells) == expected
    finally:
        record_files.joined_row = by_row
