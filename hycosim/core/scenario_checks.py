"""A scenario's actions checked against the project: which inputs may be overridden, and with
what (its run is :class:`hycosim.master.scenario.Scenario`)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hycosim.core.schema import Issue, Port, PortType, Project, ScenarioAction


@dataclass(frozen=True)
class Target:
    """An input a scenario may override: its node, its position among the node's inputs, and the
    port."""

    node: str
    index: int
    port: Port


def value_problem(port: Port, value: Any) -> str | None:
    """Why ``value`` cannot be what input ``port`` sees (its type, its shape), or None."""
    if port.shape is not None:
        if type(value) is not list or len(value) != port.size:
            return f"is an array of {port.size} elements"
        return next((why for v in value if (why := _scalar_problem(port.type, v)) is not None), None)
    return _scalar_problem(port.type, value)


# FMI's Integer (fmi2Integer, fmi3Int32 as hycosim maps its Integer ports) is a 32-bit int.
_INT_RANGE = (-2 ** 31, 2 ** 31 - 1)


def _finite(value: Any) -> bool:
    if type(value) is float:
        return math.isfinite(value)
    return type(value) is int and -1.7e308 < value < 1.7e308  # an int a float can hold (10**400 cannot)


def _scalar_problem(kind: PortType, value: Any) -> str | None:
    if kind is PortType.REAL:
        return None if _finite(value) else "takes a finite number"
    if kind is PortType.INTEGER:
        ok = type(value) is int and _INT_RANGE[0] <= value <= _INT_RANGE[1]
        return None if ok else "takes a whole number of 32 bits"
    if kind is PortType.BOOLEAN:
        return None if type(value) is bool else "takes true or false"
    if kind is PortType.STRING:
        return None if type(value) is str else "takes a string"
    return "cannot be overridden (a binary port)"


def fed_inputs(project: Project, routes: list[Any]) -> dict[str, Target]:
    """The inputs a scenario may override: those a link feeds, by ``node.port``."""
    fed = {(r.dst_node, r.dst_port) for r in routes}
    return {f"{n.nodeName}.{p.name}": Target(n.nodeName, i, p)
            for n in project.nodeLists for i, p in enumerate(n.input) if (n.nodeName, p.name) in fed}


def scenario_issues(project: Project, routes: list[Any], actions: list[ScenarioAction],
                    where: str = "scenario") -> list[Issue]:
    """Every action that cannot be taken, with its JSON path: a port no link feeds, a value its
    type or shape cannot take, a ramp on a port that is not a scalar Real, a time outside the
    run, a release of a port no earlier action overrides."""
    issues = []
    targets = fed_inputs(project, routes)
    where = where or ""
    cosim = project.coSimulation
    overridden: set[str] = set()
    for i, action in sorted(enumerate(actions), key=lambda ia: ia[1].t):
        at = f"{where}[{i}]"  # "scenario[2]", or "[2]" in a file of actions
        key = action.kind
        if not (math.isfinite(action.t) and cosim.startTime <= action.t <= cosim.stopTime):
            issues.append(Issue(f"{at}.t", f"t = {action.t} is outside the run",
                                f"from startTime {cosim.startTime:g} to stopTime {cosim.stopTime:g} s"))
            continue
        if action.parameter is not None:
            issues.extend(_parameter_issues(project, action, at))
            continue
        target = targets.get(action.target)
        if target is None:
            issues.append(Issue(f"{at}.{key}", f"{action.target!r} is no input a link feeds",
                                f"inputs a link feeds: {', '.join(sorted(targets)) or 'none'}"))
            continue
        if action.release is not None:
            if action.target not in overridden:
                issues.append(Issue(f"{at}.release", f"{action.target} is not overridden before t = {action.t:g}",
                                    "release a port an earlier action overrides"))
            overridden.discard(action.target)
            continue
        overridden.add(action.target)
        if action.ramp is not None:
            if target.port.type is not PortType.REAL or target.port.shape is not None:
                issues.append(Issue(f"{at}.ramp", f"{action.target} is no scalar Real port",
                                    "a ramp moves a Real value; give a 'value' instead"))
            for key, end in (("to", action.ramp.to), ("from", action.ramp.start)):
                if end is not None and not _finite(end):
                    issues.append(Issue(f"{at}.ramp.{key}", f"{end!r} is not a finite number"))
            continue
        why = value_problem(target.port, action.value)
        if why is not None:
            issues.append(Issue(f"{at}.value", f"{action.target} {why}, not {action.value!r}"))
    return issues


def _parameter_issues(project: Project, action: ScenarioAction, at: str) -> list[Issue]:
    """A parameter action's: a stepping node's (``node.name``), with a scalar finite value. Whether
    the model declares the name tunable is known once its node says so (its HELLO): the run
    refuses it then, before the first step (``hycosim validate`` reads an FMU's declaration)."""
    node_name, _, name = action.parameter.partition(".")
    stepping = {n.nodeName: n for n in project.stepping_nodes()}
    if node_name not in stepping or not name:
        return [Issue(f"{at}.parameter", f"{action.parameter!r} is no parameter of a stepping node",
                      f"node.parameter, the node one of {', '.join(stepping) or 'none'}")]
    if not (type(action.value) in (bool, int, str) or (type(action.value) is float and _finite(action.value))):
        return [Issue(f"{at}.value", f"{action.value!r} is no value a parameter takes",
                      "a finite number, a bool or a string")]
    if type(action.value) is int and not -(1 << 63) <= action.value < (1 << 63):
        return [Issue(f"{at}.value", f"{action.value} does not fit 64 bits")]
    return []


def load_scenario(path: Path, project: Project, routes: list[Any]) -> list[ScenarioAction]:
    """The actions of a scenario file (``--scenario FILE``: a JSON list of actions, or an object
    with a ``scenario`` list), checked as a project's ``scenario`` is; ConfigError naming the
    file and each problem's place in it."""
    from pydantic import TypeAdapter, ValidationError

    from hycosim.core.config import ConfigError, pydantic_issues

    source = str(path)
    try:
        data = json.loads(path.read_bytes())
    except OSError as exc:
        raise ConfigError(source, [Issue("(file)", f"cannot read: {exc.strerror or exc}")]) from None
    except (ValueError, RecursionError) as exc:
        raise ConfigError(source, [Issue("(file)", f"invalid JSON: {exc}")]) from None
    where = "scenario" if type(data) is dict else ""
    if type(data) is dict:
        extra = sorted(set(data) - {"scenario"})
        if extra or "scenario" not in data:
            raise ConfigError(source, [Issue("(top level)", "a scenario file is a list of actions, or an object "
                                             "with just a 'scenario' list" + (f" (not {extra})" if extra else ""))])
        data = data["scenario"]
    try:
        actions = TypeAdapter(list[ScenarioAction]).validate_python(data)
    except ValidationError as err:
        raise ConfigError(source, pydantic_issues(err, where)[:20]) from None
    issues = scenario_issues(project, routes, actions, where=where)
    if issues:
        raise ConfigError(source, issues)
    return actions
