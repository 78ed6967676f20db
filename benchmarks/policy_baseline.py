"""The paper's own formulation of the grasp policy against the engineered one, for the same
training time on this machine.

The paper's formulation (``hycosim/scenario/policy/paper.py``): state = TCP position, six joint angles,
the rod's grasp-point position and angle; action = six joint targets; Equation 6 as reward;
plain DDPG from scratch, no demonstrations. It is trained for ``--minutes`` of wall time
per seed and evaluated every ``--eval-every`` episodes (success per release angle, the
episodes of the engineered policy's evaluation). The engineered policy's curves are read
from the training folders given with ``--ours`` (``hycosim train -o DIR`` writes them): its
evaluations over its training time, its cloned start as a dashed line.

    python benchmarks/policy_baseline.py [--minutes 20] [--seeds 0] [--ours DIR ...] [--plot FILE] [--json]
                                         [--save FILE | --paper-from FILE]

``--save`` keeps the curves as JSON; ``--paper-from`` redraws with the paper's curves from
such a file instead of training it again (20 minutes a seed).

Reported, not tuned to a target.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch
from pydantic import BaseModel, ConfigDict, Field, ValidationError

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from hycosim.scenario.policy.paper import plot_against, train_paper  # noqa: E402


class Evaluation(BaseModel):
    """One point of a learning curve: training time (s) and mean success over the angles."""

    model_config = ConfigDict(extra="allow")
    seconds: float = Field(ge=0, allow_inf_nan=False)
    mean_success: float = Field(ge=0, le=1)


class SavedCurves(BaseModel):
    """What ``--save`` writes; only the paper's curves are read back."""

    model_config = ConfigDict(extra="allow")
    paper: dict[str, list[Evaluation]]


def parse_paper_curves(data: bytes, source: str) -> dict[str, list[dict]]:
    """The paper's curves from the bytes of a ``--save`` file; ValueError naming ``source``."""
    try:
        saved = SavedCurves.model_validate_json(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "the file"
        raise ValueError(f"{source}: not a file of curves written by --save ({where}: {first['msg']})") from None
    return {label: [e.model_dump() for e in run] for label, run in saved.paper.items()}


def ours_history(folder: Path) -> tuple[str, list[dict]]:
    """The label (its seed) and the evaluations of an engineered training run, from its ``last.pt``."""
    state = torch.load(folder / "last.pt", map_location="cpu", weights_only=True)
    seed = (state.get("train_config") or {}).get("seed")
    return (folder.name if seed is None else f"seed {seed}"), state["history"]["evals"]


def main() -> None:
    """Train the paper's formulation for ``--minutes`` a seed (or read its curves from
    ``--paper-from``), read the engineered policy's from ``--ours``, plot both and print their
    evaluations."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=20.0)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--eval-every", type=int, default=50)
    parser.add_argument("--eval-trials", type=int, default=5)
    parser.add_argument("--ours", type=Path, nargs="*", default=[])
    parser.add_argument("--plot", type=Path, default=Path("policy_baseline.png"))
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--save", type=Path, help="write the curves (paper's and ours) to this JSON file")
    parser.add_argument("--paper-from", type=Path, help="the paper's curves from a --save file: no training")
    args = parser.parse_args()

    paper = {}
    if args.paper_from:
        try:
            paper = parse_paper_curves(args.paper_from.read_bytes(), str(args.paper_from))
        except OSError as exc:
            sys.exit(f"{args.paper_from}: cannot read ({exc.strerror})")
        except ValueError as exc:
            sys.exit(str(exc))
    for seed in [] if args.paper_from else args.seeds:
        result = train_paper(60 * args.minutes, seed, args.eval_every, args.eval_trials)
        paper[f"seed {seed}"] = result["evals"]
        last = result["evals"][-1]
        best = max(result["evals"], key=lambda e: e["mean_success"])
        print(f"paper's formulation, seed {seed}: {result['episodes']} episodes in {result['seconds'] / 60:.1f} min; "
              f"last evaluation {_angles(last['per_angle'])}; best {_angles(best['per_angle'])} "
              f"(after {best['seconds'] / 60:.1f} min)")
    ours = {}
    for folder in args.ours:
        label, evals = ours_history(folder)
        ours[label] = evals
        best = max(evals, key=lambda e: e["mean_success"])
        print(f"engineered ({folder.name}, {label}): cloned start {_angles(_rates(evals[0]))} after "
              f"{evals[0].get('seconds', 0) / 60:.1f} min; best {_angles(_rates(best))} "
              f"(after {best.get('seconds', 0) / 60:.1f} min, episode {best['episode']})")
    plot_against(ours, paper, args.plot)
    print(f"wrote {args.plot}")
    if args.save:
        args.save.write_text(json.dumps({"paper": paper, "ours": ours}))
    if args.json:
        print(json.dumps({"paper": paper, "ours": ours}))


def _rates(evaluation: dict) -> dict[str, float]:
    return {k: v["success"] for k, v in evaluation["per_angle"].items()}


def _angles(per_angle: dict[str, float]) -> str:
    return " ".join(f"{k}°: {100 * v:.0f} %" for k, v in per_angle.items())


if __name__ == "__main__":
    main()
