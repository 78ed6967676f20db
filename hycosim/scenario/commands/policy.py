"""The grasp policy: train it, evaluate checkpoints."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from hycosim.cli.extras import require_extra
from hycosim.cli.output import err, fail, out
from hycosim.core import signals

app = typer.Typer()


@app.command()
def train(
    output: Annotated[Path, typer.Option("-o", "--output", help="folder for checkpoints and the learning curve")] = Path("runs/train"),
    episodes: Annotated[int, typer.Option(min=0, help="DDPG episodes after the demonstrations")] = 200,
    demos: Annotated[int, typer.Option(min=0, help="reference-controller episodes to learn from")] = 100,
    eval_every: Annotated[int, typer.Option(min=1, help="evaluate every N episodes")] = 20,
    eval_trials: Annotated[int, typer.Option(min=1, help="evaluation episodes per release angle")] = 10,
    select_trials: Annotated[int, typer.Option(min=0, help="episodes per angle to choose best.pt on at the end "
                                               "(0: the periodic evaluations choose)")] = 50,
    seed: Annotated[int, typer.Option(min=0, max=2**31 - 1, help="seed of the networks, the noise and the episodes")] = 0,
    ship: Annotated[Optional[Path], typer.Option(help="also write a small copy of the best checkpoint here")] = None,
) -> None:
    """Train the DDPG grasp policy (demonstrations, behaviour cloning, DDPG); resumes from OUTPUT/last.pt."""
    require_extra("scenario", "hycosim train")
    from hycosim.scenario.policy.ddpg import CheckpointError
    from hycosim.scenario.policy.progress import TrainingProgress
    from hycosim.scenario.policy.train import TrainConfig, train as run_training

    config = TrainConfig(demo_episodes=demos, episodes=episodes, eval_every=eval_every, eval_trials=eval_trials,
                         select_trials=select_trials, seed=seed)
    config.ddpg.seed = seed
    with TrainingProgress(config, err) as progress:
        try:
            result = run_training(output, config, progress.report)
        except KeyboardInterrupt as exc:
            progress.progress.stop()
            saved = output / "last.pt"
            err.print(f"{signals.describe(exc)}; " + (
                f"the same command resumes from {saved}" if saved.exists() else
                "no checkpoint yet (the first is written after the cloning phase)"), highlight=False)
            raise typer.Exit(signals.exit_code(exc)) from None
        except (ValueError, CheckpointError) as exc:
            fail(str(exc))
    if ship is not None:
        from hycosim.scenario.policy.ddpg import strip_checkpoint

        strip_checkpoint(output / "best.pt", ship)
    for when, e in (result.get("critic_error") or {}).items():
        out.print(f"critics on held-out rollouts of the cloned policy ({when.replace('_', ' ')}): mean error "
                  f"{e['mae']:.1f} on returns of mean {e['return_mean']:.1f} ({100 * e['relative']:.0f} %)",
                  highlight=False)
    if result.get("selected_episode") is not None:
        out.print(f"best.pt: the policy after {result['selected_episode']} DDPG episodes, chosen on "
                  f"{config.select_trials} fresh episodes per angle among the leading evaluations", highlight=False)
    out.print(f"best mean evaluation success {100 * result['best_mean_success']:.0f} % "
              f"({100 * result['best_mean_precise']:.0f} % within 3 mm) in "
              f"{result['trained_s']:.0f} s; checkpoints and learning_curve.png in {output}", highlight=False)


@app.command()
def evaluate(
    checkpoints: Annotated[list[Path], typer.Argument(help="policy checkpoints (.pt) to evaluate on the same episodes")],
    trials: Annotated[int, typer.Option(min=1, help="episodes per release angle")] = 100,
    workers: Annotated[int, typer.Option(min=1, max=256, help="processes to spread the episodes over")] = 2,
    seed: Annotated[int, typer.Option(min=0, max=2**31 - 1,
                                      help="first episode seed (the release phase and side are random)")] = 10_000,
    json_out: Annotated[Optional[Path], typer.Option("--json", help="also write the figures here")] = None,
) -> None:
    """Evaluate policy checkpoints in the training environment: per release angle, success, grasps
    within 3 mm (with 95 % intervals), collisions, time to grasp and distance."""
    require_extra("scenario", "hycosim evaluate")
    import json

    from hycosim.scenario.policy.ddpg import CheckpointError, load_policy
    from hycosim.scenario.policy.train import evaluate_checkpoint

    def save(figures: dict) -> None:  # after each checkpoint: what was measured stays on disk
        if json_out is None:
            return
        try:
            json_out.write_text(json.dumps(figures, indent=1))
        except OSError as exc:
            fail(f"--json: cannot write {json_out} ({exc.strerror or exc})")

    figures: dict = {}
    save(figures)  # a file that cannot be written is named before the episodes, not after
    for path in checkpoints:
        try:
            meta = load_policy(path).meta
        except CheckpointError as exc:
            fail(str(exc))
        figures[str(path)] = {"episodes_trained": meta.get("episodes"),
                              "per_angle": evaluate_checkpoint(path, trials, workers, seed)}
        save(figures)
        out.print(f"{path} (DDPG episodes {meta.get('episodes')}), {trials} episodes per angle:", highlight=False)
        for angle, v in figures[str(path)]["per_angle"].items():
            lo, hi = v["success_95"]
            grasp = f"{v['grasp_time_s']:.2f} s" if v["grasp_time_s"] is not None else "-"
            out.print(f"  {angle:>3}°  success {100 * v['success']:5.1f} % ({100 * lo:.0f}–{100 * hi:.0f})  "
                      f"≤ 3 mm {100 * v['precise']:5.1f} %  collisions {100 * v['collision']:4.1f} %  "
                      f"time to grasp {grasp}  distance {v['distance_mm']:.2f} mm", highlight=False)
