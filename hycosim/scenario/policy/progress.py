"""Training's progress shown as rich progress bars: one bar per phase (demonstrations, DAgger,
critics on the cloned policy, DDPG with its running return and success, choosing best.pt) and
each evaluation as a line. :meth:`TrainingProgress.report` is what :func:`train` calls."""

from __future__ import annotations

from typing import Any

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from hycosim.scenario.policy.train import TrainConfig

# The DDPG bar's running figures are over this many episodes.
WINDOW = 20


class TrainingProgress:
    """A context manager: the bars live while training runs."""

    def __init__(self, config: TrainConfig, console: Console):
        self.progress = Progress(TextColumn("[bold]{task.description}"), BarColumn(),
                                 TextColumn("{task.completed}/{task.total}"), TextColumn("{task.fields[info]}"),
                                 TimeElapsedColumn(), console=console)
        self._tasks = {
            "demonstrations": self.progress.add_task("demonstrations", total=config.demo_episodes, info=""),
            "dagger": self.progress.add_task("DAgger", total=config.dagger_rounds * config.dagger_episodes, info=""),
            "rollouts": self.progress.add_task("critics on the cloned policy", total=None, info=""),
            "ddpg": self.progress.add_task("DDPG", total=config.episodes, info=""),
            "select": self.progress.add_task("choosing best.pt", total=None, info=""),
        }
        self.returns: list[float] = []
        self.successes: list[bool] = []

    def __enter__(self) -> TrainingProgress:
        self.progress.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.progress.stop()

    def report(self, d: dict) -> None:
        """Take one of training's progress records (its ``phase`` says which)."""
        phase = d["phase"]
        if phase in ("demonstrations", "dagger"):
            self.progress.update(self._tasks[phase], completed=d["done"])
        elif phase in ("select", "rollouts"):
            self.progress.update(self._tasks[phase], completed=d["done"], total=d["total"])
        elif phase == "ddpg":
            self.returns.append(d["return"])
            self.successes.append(d["success"])
            last, hits = self.returns[-WINDOW:], self.successes[-WINDOW:]
            self.progress.update(self._tasks["ddpg"], completed=d["episode"],
                                 info=f"mean return {sum(last) / len(last):7.1f}  "
                                      f"success {100 * sum(hits) / len(hits):3.0f} %")
        elif phase in ("eval", "pretrained"):
            text = ", ".join(f"{k}°: {100 * v['success']:.0f} % ({100 * v['precise']:.0f} % ≤ 3 mm)"
                             for k, v in d["per_angle"].items())
            self.progress.console.print(f"evaluation after {d.get('episode', 0)} episodes: {text}", highlight=False)
