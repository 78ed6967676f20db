"""The rows of a run in one process are written by a process of its own (server/row_writer.py):
the same bytes as the recorder's own, the same answers for a checkpoint's ends and cuts, and the
guarantees of the records when the writer dies and when the master dies (a full disk:
tests/test_faults.py, in processes and in process)."""

from __future__ import annotations

import os
import signal

import pytest

from hycosim.master.record_files import RecordError
from hycosim.master.row_writer import LocalRows, RowWriter
from tests.helpers import descendants, reap, recorded_rows, running, spawn, wait_for
from tests.test_faults import _pair

FORMAT = "%d,%r,%.9f,%s,%s,%.9f\r\n"


def _rows(kind, run_dir, resume_at=None):
    return kind(run_dir, FORMAT, resume_at or {})


def _write(rows, first: int, count: int) -> None:
    for k in range(first, first + count):
        rows.values([k, k * 0.1, "free", k / 3, -k, 2**40 + k])
        rows.timing((k, k * 0.1, 1e-6 * k, "a", "", 2e-6))


@pytest.mark.parametrize("kind", [LocalRows, RowWriter])
def test_checkpoint_ends_cuts_and_a_resume_give_the_rows_a_run_straight_through_writes(tmp_path, kind):
    straight = tmp_path / "straight"
    straight.mkdir()
    rows = _rows(LocalRows, straight)
    _write(rows, 0, 900)
    assert rows.close() == []

    cut_back = tmp_path / "cut"
    cut_back.mkdir()
    rows = _rows(kind, cut_back)
    _write(rows, 0, 300)
    ends = rows.positions()
    assert ends == {name: (cut_back / name).stat().st_size for name in ends}  # everything sent is written
    _write(rows, 300, 500)  # a stretch taken again after a recovery
    rows.cut(ends)
    for k in range(300, 600):  # an answer that comes while rows are sent is kept for its wait
        _write(rows, k, 1)
        ends = rows.positions()
        assert ends["values.csv"] == (cut_back / "values.csv").stat().st_size
    _write(rows, 600, 77)  # what a killed server had written after its last checkpoint
    assert rows.close() == []
    rows = _rows(kind, cut_back, ends)  # a resume from that checkpoint
    _write(rows, 600, 300)
    assert rows.close() == []
    for name in ("values.csv", "timing.csv"):
        assert (cut_back / name).read_bytes() == (straight / name).read_bytes()


@pytest.mark.parametrize("kind", [LocalRows, RowWriter])
def test_rows_of_both_ways_and_quoted_ones_between_them_are_written_in_the_order_they_came(tmp_path, kind):
    """LocalRows keeps a row's cells until a flush and formats the rows then: a row that goes
    through csv.writer (a header, a point of another timing layout, a String port's row) between
    them still lands in its place, and every row is its text as a row at a time would have it."""
    from hycosim.master.record_files import joined_row

    out = tmp_path / "run"
    out.mkdir()
    rows = _rows(kind, out)
    values, timing = [], []
    for k in range(40):
        if k % 7 == 3:
            rows.csv_row("timing.csv", [k, "a, quoted", 1.5])
            rows.csv_row("values.csv", [k, 0.5, "free", 'say "x"'])
            timing.append(f'{k},"a, quoted",1.5\r\n')
            values.append(f'{k},0.5,free,"say ""x"""\r\n')
        cells = [k, k * 0.1, "free", k / 3, 1e-5 * k, 2 ** 70 + k, True]
        rows.values(cells)
        rows.timing((k, k * 0.1, 1e-6 * k, "a", "", 2e-6))
        values.append(joined_row(cells))
        timing.append(FORMAT % (k, k * 0.1, 1e-6 * k, "a", "", 2e-6))
        if k == 20:
            rows.flush(k)
    assert rows.close() == []
    assert (out / "values.csv").read_bytes().decode() == "".join(values)
    assert (out / "timing.csv").read_bytes().decode() == "".join(timing)


def test_a_row_writer_that_dies_stops_the_run_at_the_next_flush_with_what_it_wrote_named(tmp_path):
    rows = RowWriter(tmp_path, FORMAT, {}, timeout=5.0)
    _write(rows, 0, 10)
    rows.flush(9)
    wait_for(lambda: (tmp_path / "values.csv").stat().st_size > 0, 10, "the first rows on disk")
    assert rows.pid in descendants(os.getpid())
    os.kill(rows.pid, signal.SIGKILL)
    wait_for(lambda: not running(rows.pid), 10, "the writer gone")
    _write(rows, 10, 10)
    with pytest.raises(RecordError, match=r"the run's row writer stopped at step 19 \(exit code -9\)"):
        rows.flush(19)
    assert rows.close()  # says what could not be written
    assert (tmp_path / "values.csv").read_text().splitlines()[:10] == \
        [f"{k},{k * 0.1!r},free,{k / 3!r},{-k},{2**40 + k}" for k in range(10)]


def test_a_killed_run_in_one_process_leaves_its_rows_whole_and_its_writer_ends(tmp_path):
    cfg = _pair(tmp_path, stepSize=1.0, stopTime=5e6, realTime=False)
    runs = tmp_path / "runs"
    run = spawn("run", str(cfg), "--in-process", "--runs-dir", str(runs), "--no-progress")
    try:
        wait_for(lambda: recorded_rows(runs) > 3000, 60, "rows on disk")
        writers = [p for p in descendants(run.pid) if running(p)]
        assert len(writers) == 1
        run.kill()  # as a crashed FMU takes the process down
        run.wait(timeout=10)
        wait_for(lambda: not running(writers[0]), 10, "the writer ended")
    finally:
        reap(run)
    text = (next(runs.iterdir()) / "values.csv").read_bytes().decode()
    assert text.endswith("\r\n")  # whole rows only
    rows = text.split("\r\n")[1:-1]
    assert len(rows) > 3000
    for k, row in enumerate(rows):
        step, t, mode, y, v, gy, gu = row.split(",")
        assert (int(step), float(t), mode) == (k, float(k), "free")
        assert float(gu) == float(y) and (k == 0 or float(gy) == float(rows[k - 1].split(",")[3]))


def test_an_answer_read_while_rows_are_sent_is_kept_for_the_wait_that_asks_for_it(tmp_path, monkeypatch):
    import time

    from hycosim.core.fd_wait import ready
    from hycosim.master import row_writer

    def late_poll(fd, *, write=False, timeout=None):
        if timeout == 0.0:  # the poll after a send: the writer's answer has come by then
            time.sleep(0.05)
        return ready(fd, write=write, timeout=timeout)

    rows = RowWriter(tmp_path, FORMAT, {}, timeout=5.0)
    monkeypatch.setattr(row_writer, "ready", late_poll)
    _write(rows, 0, 5)
    ends = rows.positions()
    assert ends["values.csv"] == (tmp_path / "values.csv").stat().st_size > 0
    rows.cut(ends)
    assert rows.close() == []


def test_the_writer_serves_a_process_whose_descriptors_pass_1024(tmp_path, high_descriptors):
    """A master with over a thousand files open (a Dask worker after many runs) gets the
    writer's pipes numbered past select()'s limit: rows, a checkpoint's ends and the close
    work as anywhere."""
    rows = RowWriter(tmp_path, FORMAT, {}, timeout=5.0)
    assert min(rows._to, rows._from) >= 1024
    _write(rows, 0, 600)
    ends = rows.positions()
    assert ends["values.csv"] == (tmp_path / "values.csv").stat().st_size > 0
    assert rows.close() == []
    assert len((tmp_path / "values.csv").read_text().splitlines()) == 600


@pytest.mark.parametrize("kind", [LocalRows, RowWriter])
def test_rows_of_any_widths_between_flushes_are_the_text_csv_writer_gives_them(tmp_path, kind):
    """Rows wait for a flush in one flat list (LocalRows): rows of different widths, a flush
    among them, and the timing rows made by one format for many come out one by one, as
    csv.writer and the format write each."""
    import csv
    import io

    rows = _rows(kind, tmp_path)
    values = [[k, k * 0.25, "free", *[k / 7] * (k % 4)] for k in range(40)]
    timing = [(k, k * 0.25, 1e-6 * k, "a", "", 2e-6 * k) for k in range(40)]
    for k in range(40):
        rows.values(values[k])
        rows.timing(timing[k])
        if k == 17:
            rows.flush(k)
    assert rows.close() == []
    text = io.StringIO()
    csv.writer(text).writerows(values)
    assert (tmp_path / "values.csv").read_bytes().decode() == text.getvalue()
    assert (tmp_path / "timing.csv").read_bytes().decode() == "".join(FORMAT % cells for cells in timing)
