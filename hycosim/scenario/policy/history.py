"""The training record a ``last.pt`` carries, checked before a resume reads it.

A training folder is a user's file: a ``last.pt`` can pass the config-hash check and still
hold a history of another shape (edited by hand, or written by another version). The
trainer reads it to score evaluations, to aim failure-focused episodes and to draw the
learning curve, so its shape is checked once, here, and a mismatch is named.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, ValidationError

Share = Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
Episode = Annotated[int, Field(ge=0)]


class _Record(BaseModel):
    # strict: a "true" string or a float episode count is another file, not this one;
    # extra entries are kept (figures a later version adds are not a reason to refuse).
    model_config = ConfigDict(strict=True, extra="allow")


class AngleFigures(_Record):
    """One release angle's figures in an evaluation: the share of grasps, of precise grasps, and the
    mean time to grasp."""

    success: Share
    precise: Share = 0.0
    time_s: Annotated[float, Field(ge=0.0, allow_inf_nan=False)]


class Evaluation(_Record):
    """An evaluation during training: after which DDPG episode, each angle's figures and the mean
    success."""

    episode: Episode
    per_angle: dict[str, AngleFigures]
    mean_success: Share


class EpisodeRecord(_Record):
    """One training episode: its number, return, whether it grasped and its release angle."""

    episode: Episode
    return_: Finite = Field(alias="return")
    success: bool
    angle: Finite | None = None


class TrainingHistory(_Record):
    """What a ``last.pt`` records of its training: every episode's return and every evaluation (the
    cloned start's first)."""

    returns: list[EpisodeRecord]
    evals: list[Evaluation] = Field(min_length=1)  # the cloned start's, written before any resume


class ResumeError(ValueError):
    """A ``last.pt`` whose training record cannot be gone on from."""


def check_resumable(state: dict, angles: tuple[float, ...]) -> tuple[dict, int, float]:
    """The history, episodes done and training seconds of a training checkpoint ``state``,
    each checked; every evaluation must hold figures for each of ``angles``. ResumeError
    says which entry is wrong."""
    try:
        checked = TrainingHistory.model_validate(state["history"])
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        raise ResumeError(f"its history does not hold a training record ({where or 'history'}: {first['msg']})") from None
    # What was checked, not what was read: a figure the check took as a number (a one-element
    # tensor passes as a float) is a number from here on.
    history = checked.model_dump(by_alias=True)
    for evaluation in history["evals"]:
        missing = [f"{a:g}" for a in angles if f"{a:g}" not in evaluation["per_angle"]]
        if missing:
            raise ResumeError(f"its evaluation at episode {evaluation['episode']} has no figures for "
                              f"{', '.join(missing)}°")
    episodes = state["episodes"]
    if type(episodes) is not int or episodes < 0:
        raise ResumeError(f"its episode count {episodes!r} is not a whole number of episodes")
    trained = state.get("trained_s")
    if trained is None:  # checkpoints written before the training time was recorded
        trained = 0.0
    if type(trained) not in (int, float) or not 0.0 <= trained < float("inf"):
        raise ResumeError(f"its training time {trained!r} is not a number of seconds")
    return history, episodes, float(trained)
