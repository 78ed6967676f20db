"""``hycosim sweep``: many runs of one project, its parameters varied, on Dask workers."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Optional

import typer

from hycosim.cli.output import err, fail, out

app = typer.Typer()


@app.command()
def sweep(
    project: Path,
    settings: Annotated[list[str], typer.Option("--set", help="node.param=v1,v2,… or node.param=uniform(a,b), "
                                                               "normal(mean,sd), choice(v1,…) (with --samples)")],
    output: Annotated[Path, typer.Option("-o", "--output", help="the folder of the runs and their table")] = Path("sweep"),
    zipped: Annotated[bool, typer.Option("--zip/--grid", help="pair the i-th values of each set (default: every "
                                                               "combination)")] = False,
    samples: Annotated[Optional[int], typer.Option(help="draw this many runs from the distributions")] = None,
    seed: Annotated[int, typer.Option(help="the draws' seed")] = 0,
    workers: Annotated[Optional[int], typer.Option(min=1, help="a local cluster of this many worker processes "
                                                                "(default 1)")] = None,
    scheduler: Annotated[Optional[str], typer.Option(help="a running Dask scheduler, tcp://host:8786")] = None,
    metric: Annotated[list[str], typer.Option("--metric", help="node.port:final|min|max|mean, a column of the "
                                                                "table")] = [],
    timeout: Annotated[Optional[float], typer.Option(help="seconds a run may take; past them it is stopped and "
                                                           "recorded as timeout")] = None,
    values: Annotated[bool, typer.Option("--values", help="also every run's values in OUT/values.parquet")] = False,
    resume: Annotated[Optional[Path], typer.Option(help="go on with the sweep in this folder: the runs its table "
                                                         "holds as completed are skipped")] = None,
) -> None:
    """Run PROJECT once per variant of its parameters, each run on a Dask worker.

    The workers are a local cluster, or a scheduler's by address. OUT/runs.parquet holds a row
    per run: its parameters, outcome, message, steps/s and the metrics asked for."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    from hycosim.ensemble.sweep import SweepError, Tally, sweep as run_sweep

    if workers is not None and scheduler is not None:
        fail("--workers and --scheduler: a local cluster or one by address, not both")
    out_dir = resume if resume is not None else output
    bar = Progress(TextColumn("[bold]sweep"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                   TextColumn("{task.fields[state]}"), TimeElapsedColumn(), TimeRemainingColumn(), console=err,
                   transient=False)
    task = None

    def shown(tally: Tally) -> None:
        nonlocal task
        if task is None:
            task = bar.add_task("sweep", total=tally.total, state="")
            bar.start()
        bar.update(task, completed=tally.done + tally.failed,
                   state=f"done {tally.done} · failed {tally.failed} · running {tally.running}")

    try:
        table = run_sweep(project, list(settings), zipped=zipped, samples=samples, seed=seed, workers=workers,
                          scheduler=scheduler, metrics=list(metric), out=out_dir, timeout=timeout, values=values,
                          resume=resume is not None, on_progress=shown)
    except SweepError as exc:
        bar.stop()
        fail(str(exc))
    except KeyboardInterrupt:
        bar.stop()
        err.print(f"interrupted: the runs that ended are in {out_dir / 'runs.parquet'}", highlight=False)
        raise typer.Exit(130) from None
    bar.stop()
    rows = table.to_dict("records") if hasattr(table, "to_dict") else table.to_pylist()
    failed = [r for r in rows if r["outcome"] != "completed"]
    rates = [r["steps_per_s"] for r in rows if r["outcome"] == "completed" and not math.isnan(r["steps_per_s"])]
    out.print(f"{out_dir / 'runs.parquet'}: {len(rows)} runs, {len(rows) - len(failed)} completed, "
              f"{len(failed)} not" + (f"; {sum(rates) / len(rates):,.0f} steps/s a run" if rates else ""),
              highlight=False)
    for r in failed[:5]:
        out.print(f"  run {r['run']}: {r['outcome']}: {r['message']}", highlight=False)
    if failed:
        raise typer.Exit(1)
