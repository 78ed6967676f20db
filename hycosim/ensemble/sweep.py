"""A sweep: every variant checked before any run starts, each handed to a Dask worker (a
``LocalCluster`` of ``workers`` processes, or a scheduler by address), and its table,
``OUT/runs.parquet``, written again as each run ends, so that what finished is on disk whatever
happens to the rest (a failed run, a worker that dies, Ctrl-C). ``resume`` skips the runs a
table in ``OUT`` holds as completed."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hycosim.ensemble.cluster import dask_client, each_ended, require_ensemble
from hycosim.ensemble.runs import Metric, parse_metric, run_variant, with_parameters
from hycosim.ensemble.variants import Setting, SweepError, parse_setting, variants

RUNS_TABLE = "runs.parquet"
VALUES_TABLE = "values.parquet"


@dataclass
class Tally:
    """Where a sweep stands, for a progress bar."""

    total: int
    done: int = 0
    failed: int = 0

    @property
    def running(self) -> int:
        """Runs neither done nor failed yet."""
        return self.total - self.done - self.failed


def _project(project: str | Path | dict[str, Any]) -> tuple[dict[str, Any], Path]:
    """The project as a dict with absolute paths, and the folder its files are named from."""
    from hycosim.api import absolute_paths
    from hycosim.core import json_text

    if isinstance(project, dict):
        return absolute_paths(project, Path.cwd()), Path.cwd()
    path = Path(project)
    from hycosim.fmi.osp import OspError, imported_structure, is_structure
    from hycosim.fmi.ssp import SspError, imported_project

    try:
        if is_structure(path):
            path, _ = imported_structure(path)
        elif path.suffix.lower() == ".ssp":
            path = imported_project(path)
        doc = json_text.loads(path.read_bytes())
    except (OspError, SspError) as exc:
        raise SweepError(str(exc)) from None
    except (OSError, ValueError) as exc:
        raise SweepError(f"{path}: cannot read the project ({exc})") from None
    if type(doc) is not dict:
        raise SweepError(f"{path}: holds no project object")
    return absolute_paths(doc, path.parent), path.parent


def check(doc: dict[str, Any], runs: list[dict[str, Any]], metrics: list[Metric]) -> None:
    """SweepError for the first variant the project's checks refuse (a parameter its node does
    not declare, a value of the wrong type or out of range) or a metric naming no port."""
    from hycosim.core.config import ConfigError, parse_project
    from hycosim.node.loader import NodeLoadError, check_node

    try:
        loaded = parse_project(doc, "the project")
    except ConfigError as exc:
        raise SweepError(f"{exc.source}: " + "; ".join(i.render() for i in exc.issues)) from None
    ports = {f"{n.nodeName}.{p.name}" for n in loaded.project.nodeLists for p in (*n.input, *n.output)}
    for m in metrics:
        if m.port not in ports:
            raise SweepError(f"--metric {m.column}: the project has no port {m.port}")
    nodes = {n.nodeName for n in loaded.project.nodeLists}
    for key in runs[0]:
        if key.split(".", 1)[0] not in nodes:
            raise SweepError(f"--set {key}: the project has no node {key.split('.', 1)[0]!r}")
    for i, values in enumerate(runs):
        try:
            varied = parse_project(with_parameters(doc, values), "the project")
        except ConfigError as exc:
            raise SweepError(f"run {i} ({_show(values)}): " + "; ".join(x.render() for x in exc.issues)) from None
        for node in {key.split(".", 1)[0] for key in values}:
            spec = varied.project.node(node)
            try:
                check_node(spec, Path.cwd(), varied.project.coSimulation)
            except NodeLoadError as exc:
                raise SweepError(f"run {i} ({_show(values)}): {exc}") from None
            if not spec.fmu and not spec.model:
                raise SweepError(f"--set {node}...: node {node!r} has no model or FMU to take parameters")


def _show(values: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in values.items())


def _table(rows: list[dict[str, Any]]) -> Any:
    import pyarrow as pa

    rows = sorted(rows, key=lambda r: r["run"])
    columns = list(dict.fromkeys(k for r in rows for k in r))
    return pa.table({c: [r.get(c) for r in rows] for c in columns})


def _write(out: Path, rows: list[dict[str, Any]]) -> None:
    """The table of the runs that ended, written whole (a temporary file, then renamed)."""
    import pyarrow.parquet as pq

    tmp = out / (RUNS_TABLE + ".tmp")
    pq.write_table(_table(rows), tmp)
    tmp.replace(out / RUNS_TABLE)


def _finished(out: Path) -> list[dict[str, Any]]:
    """The rows of a table a sweep left in ``out`` whose run completed."""
    import pyarrow.parquet as pq

    path = out / RUNS_TABLE
    if not path.is_file():
        return []
    try:
        rows = pq.read_table(path).to_pylist()
    except Exception as exc:  # noqa: BLE001 - a damaged table: named, the sweep does not start
        raise SweepError(f"{path}: cannot read the table to resume from ({type(exc).__name__}: {exc})") from None
    # A table is a file a user may have edited: only rows naming a run by number count.
    return [r for r in rows if r.get("outcome") == "completed" and type(r.get("run")) is int]


def sweep(project: str | Path | dict[str, Any], parameters: dict[str, Any] | list[str], *, zipped: bool = False,
          samples: int | None = None, seed: int = 0, workers: int | None = None, scheduler: str | None = None,
          metrics: list[str] = (), out: str | Path = "sweep", timeout: float | None = None, values: bool = False,
          resume: bool = False, on_progress: Callable[[Tally], None] | None = None) -> Any:
    """Run every variant of ``project`` that ``parameters`` asks for (``{"node.param": [v1, v2]
    or "uniform(a,b)"}``, or ``--set`` texts), each in process on a Dask worker, and return their
    table (a pandas DataFrame where pandas is installed, else a pyarrow Table), which is also
    ``out/runs.parquet``; with ``values``, every completed run's values with a run column in
    ``out/values.parquet``. SweepError for what is wrong before any run starts."""
    require_ensemble()
    texts = parameters if isinstance(parameters, list) else [
        f"{k}={v}" if isinstance(v, str) else f"{k}=" + ",".join(json.dumps(x) for x in v)
        for k, v in parameters.items()]
    settings: list[Setting] = [parse_setting(t) for t in texts]
    runs = variants(settings, zipped=zipped, samples=samples, seed=seed)
    wanted = [parse_metric(m) for m in metrics]
    if timeout is not None and not (math.isfinite(timeout) and timeout > 0):
        raise SweepError(f"--timeout {timeout}: a positive number of seconds")
    doc, _ = _project(project)
    check(doc, runs, wanted)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = _finished(out) if resume else []
    skip = {r["run"] for r in rows}
    todo = [(i, v) for i, v in enumerate(runs) if i not in skip]
    tally = Tally(len(runs), done=len(rows))
    if on_progress:
        on_progress(tally)
    if todo:
        _run_all(doc, todo, out, timeout, wanted, workers, scheduler, rows, tally, on_progress)
    if values:
        _values(out, rows)
    table = _table(rows)
    try:
        return table.to_pandas()
    except ImportError:
        return table


def _run_all(doc: dict[str, Any], todo: list[tuple[int, dict[str, Any]]], out: Path, timeout: float | None,
             metrics: list[Metric], workers: int | None, scheduler: str | None, rows: list[dict[str, Any]],
             tally: Tally, on_progress: Callable[[Tally], None] | None) -> None:
    """Hand the runs to Dask; a row for each as it ends, the table written each time."""
    jobs = [((i, v), (doc, i, v, str(out.resolve()), timeout, metrics)) for i, v in todo]
    try:
        with dask_client(workers, scheduler) as client:
            for (i, v), row, error in each_ended(client, run_variant, jobs):
                if error is not None:  # a worker that died, or a run that raised past its row
                    row = {"run": i, **v, "outcome": "failed", "message": f"{type(error).__name__}: {error}",
                           "steps_per_s": math.nan, "wall_s": math.nan, "run_dir": ""}
                    row.update({m.column: math.nan for m in metrics})
                rows.append(row)
                if row["outcome"] == "completed":
                    tally.done += 1
                else:
                    tally.failed += 1
                _write(out, rows)
                if on_progress:
                    on_progress(tally)
    finally:
        if rows:
            _write(out, rows)


def _values(out: Path, rows: list[dict[str, Any]]) -> None:
    """Every completed run's values.csv, a run column first, as one Parquet table."""
    import pyarrow as pa
    import pyarrow.csv as pcsv
    import pyarrow.parquet as pq

    tables = []
    for row in sorted(rows, key=lambda r: r["run"]):
        path = Path(row["run_dir"]) / "values.csv" if row.get("run_dir") else None
        if row["outcome"] != "completed" or path is None or not path.is_file():
            continue
        table = pcsv.read_csv(path)
        tables.append(table.add_column(0, "run", pa.array([row["run"]] * table.num_rows, pa.int64())))
    if tables:
        pq.write_table(pa.concat_tables(tables, promote_options="default"), out / VALUES_TABLE)
