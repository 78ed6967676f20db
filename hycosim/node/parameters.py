"""Checks of a node entry's parameter values, for the models' ``parameter_problems``.

A model reads its parameters in ``setup``, in the node's own process, once the run has
started: a length of "0.6 m" there ended the node with a ValueError, and a negative length
ran the whole scenario with a rod that cannot be grasped. The loader asks the model's
class first (``hycosim validate`` and every run), as it checks the parameters' names.
Each check gives a sentence naming the parameter, or None when the value fits (or is
absent: the model's default applies).
"""

from __future__ import annotations

import json
import math
from typing import Any


def _is_number(value: Any) -> bool:
    # JSON true/false are bools, which Python would take for 1 and 0
    return type(value) in (int, float) and math.isfinite(value)


def number(parameters: dict[str, Any], name: str, *, above: float | None = None, at_least: float | None = None,
           at_most: float | None = None, whole: bool = False) -> str | None:
    """Why ``parameters[name]`` is not a finite number in the range given, or None."""
    if name not in parameters:
        return None
    value = parameters[name]
    kind = "a whole number" if whole else "a finite number"
    if not _is_number(value) or (whole and value != int(value)):
        return f"parameter {name!r} is {json_repr(value)}, not {kind}"
    if above is not None and not value > above:
        return f"parameter {name!r} is {value!r}; it must be above {above:g}"
    if at_least is not None and not value >= at_least:
        return f"parameter {name!r} is {value!r}; it must be at least {at_least:g}"
    if at_most is not None and not value <= at_most:
        return f"parameter {name!r} is {value!r}; it must be at most {at_most:g}"
    return None


def point(parameters: dict[str, Any], name: str, within: float | None = None) -> str | None:
    """Why ``parameters[name]`` is not three finite numbers (x, y, z in m), each at most
    ``within`` from 0 if given, or None."""
    if name not in parameters:
        return None
    value = parameters[name]
    if not (type(value) is list and len(value) == 3 and all(_is_number(v) for v in value)):
        return f"parameter {name!r} is {json_repr(value)}, not three finite numbers [x, y, z]"
    if within is not None and any(abs(v) > within for v in value):
        return f"parameter {name!r} is {json_repr(value)}; each coordinate must be within ±{within:g}"
    return None


def flag(parameters: dict[str, Any], name: str) -> str | None:
    """Why ``parameters[name]`` is not true or false, or None."""
    if name in parameters and type(parameters[name]) is not bool:
        return f"parameter {name!r} is {json_repr(parameters[name])}, not true or false"
    return None


def json_repr(value: Any) -> str:
    """A value as the project file spells it, cut short."""
    try:
        text = json.dumps(value, allow_nan=True)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def problems(*found: str | None) -> list[str]:
    """The checks that found something."""
    return [f for f in found if f is not None]
