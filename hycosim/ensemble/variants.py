"""The runs a sweep asks for: each ``--set node.param=...`` a list of values or a distribution,
combined as a grid (every combination) or zipped (the i-th value of each), or drawn ``samples``
times from a seeded generator. What is malformed is a SweepError naming the setting."""

from __future__ import annotations

import itertools
import math
import random
import re
from dataclasses import dataclass
from typing import Any

from hycosim.core import json_text

_SET = re.compile(r"^(?P<node>[A-Za-z][A-Za-z0-9_\-]*)\.(?P<name>[^=\s]+)=(?P<value>.*)$", re.S)
_DRAW = re.compile(r"^(?P<kind>uniform|normal|choice)\((?P<args>.*)\)$", re.S)


class SweepError(ValueError):
    """A sweep that cannot start: the message names the setting, the node or the parameter."""


@dataclass(frozen=True)
class Setting:
    """One parameter's values (``values``) or the distribution drawn from (``draw``: kind, args)."""

    node: str
    name: str
    values: tuple[Any, ...] = ()
    draw: tuple[str, tuple[Any, ...]] | None = None

    @property
    def key(self) -> str:
        """The setting as ``node.name``."""
        return f"{self.node}.{self.name}"


def _scalar(text: str, where: str) -> Any:
    """A value as written: a JSON number, true/false or a quoted string; else the text itself."""
    text = text.strip()
    if not text:
        raise SweepError(f"{where}: an empty value")
    try:
        value = json_text.loads(text)
    except ValueError:  # not JSON (nested too deeply included): the text itself
        return text
    if isinstance(value, (dict, list)) or value is None:
        raise SweepError(f"{where}: {text!r} is no scalar value")
    if isinstance(value, float) and not math.isfinite(value):
        raise SweepError(f"{where}: {text!r} is not finite")
    return value


def parse_setting(text: str) -> Setting:
    """``node.param=v1,v2,…`` or ``node.param=uniform(a,b)`` / ``normal(m,s)`` / ``choice(v1,…)``."""
    where = f"--set {text!r}"
    match = _SET.match(text)
    if match is None:
        raise SweepError(f"{where}: write node.parameter=value[,value…] or node.parameter=uniform(a,b), "
                         "normal(mean,sd) or choice(v1,v2,…)")
    node, name, value = match["node"], match["name"], match["value"].strip()
    drawn = _DRAW.match(value)
    if drawn is None:
        values = tuple(_scalar(v, where) for v in value.split(","))
        return Setting(node, name, values=values)
    kind, args = drawn["kind"], tuple(_scalar(v, where) for v in drawn["args"].split(","))
    if kind in ("uniform", "normal"):
        if len(args) != 2 or not all(type(a) in (int, float) for a in args):
            raise SweepError(f"{where}: {kind} takes two numbers")
        if kind == "uniform" and not args[0] < args[1]:
            raise SweepError(f"{where}: uniform(a,b) needs a < b")
        if kind == "normal" and not args[1] > 0:
            raise SweepError(f"{where}: normal(mean,sd) needs sd > 0")
    return Setting(node, name, draw=(kind, args))


def variants(settings: list[Setting], zipped: bool = False, samples: int | None = None,
             seed: int = 0) -> list[dict[str, Any]]:
    """Each run's values by ``node.param``: the lists as a grid or zipped; with ``samples``, that
    many draws of the distributions (a single value held in every draw)."""
    if not settings:
        raise SweepError("no --set: a sweep varies at least one parameter")
    keys = [s.key for s in settings]
    if len(set(keys)) != len(keys):
        raise SweepError(f"--set: {next(k for k in keys if keys.count(k) > 1)} is set twice")
    drawn = [s for s in settings if s.draw is not None]
    if samples is not None:
        if samples < 1:
            raise SweepError(f"--samples {samples}: at least one run")
        lists = [s for s in settings if s.draw is None and len(s.values) != 1]
        if lists:
            raise SweepError(f"--set {lists[0].key}: a list of values with --samples; give one value or a "
                             "distribution")
        rng = random.Random(seed)
        return [{s.key: s.values[0] if s.draw is None else _draw(rng, s.draw) for s in settings}
                for _ in range(samples)]
    if drawn:
        raise SweepError(f"--set {drawn[0].key}: a distribution needs --samples N")
    if zipped:
        lengths = {s.key: len(s.values) for s in settings}
        if len(set(lengths.values())) != 1:
            raise SweepError("--zip over sets of different lengths: "
                             + ", ".join(f"{k} has {n}" for k, n in lengths.items()))
        return [dict(zip(keys, row)) for row in zip(*(s.values for s in settings))]
    return [dict(zip(keys, row)) for row in itertools.product(*(s.values for s in settings))]


def _draw(rng: random.Random, draw: tuple[str, tuple[Any, ...]]) -> Any:
    kind, args = draw
    if kind == "uniform":
        return rng.uniform(args[0], args[1])
    if kind == "normal":
        return rng.gauss(args[0], args[1])
    return rng.choice(args)
