"""Time-triggered manipulation of a run's inputs (a scenario; fault injection), as libcosim's
manipulators and ECOS's scenarios do it.

An action at time t overrides an input that a link feeds, with a value or a ramp, or releases
it to its links again. Which actions are in force at a point follows from the point's time
alone (the latest action on each port at or before it), so a run rolled back to a checkpoint,
or resumed from one, has the same overrides there as it had; the record of the actions that
took effect is rewound with it. Actions come from the project's ``scenario``, from
``--scenario FILE`` and from a Python caller (:meth:`Scenario.add`).
"""

from __future__ import annotations

from typing import Any

from hycosim.core.scenario_checks import Target, fed_inputs
from hycosim.core.schema import Port, PortType, Project, ScenarioAction

# A point "at" an action's time: the grid's own rounding, as the guards allow it.
_AT = 1e-9
_UNSET = object()


def from_meta(value: Any, project: Project, routes: list[Any]) -> list[ScenarioAction]:
    """The ``--scenario`` actions a run kept in its ``meta.json`` (a resumed run takes them back),
    checked as a scenario file's are: ValueError saying what is wrong with them."""
    from pydantic import TypeAdapter, ValidationError

    from hycosim.core.scenario_checks import scenario_issues

    try:
        actions = TypeAdapter(list[ScenarioAction]).validate_python(value)
    except ValidationError as err:
        first = err.errors()[0]
        raise ValueError(f"its scenario cannot be read ({'.'.join(map(str, first['loc']))}: {first['msg']})") from None
    issues = scenario_issues(project, routes, actions)
    if issues:
        raise ValueError(f"its scenario cannot be taken: {issues[0].render()}")
    return actions


class Scenario:
    """The actions of one run, and what they make of its inputs at each point."""

    def __init__(self, project: Project, routes: list[Any], actions: list[ScenarioAction]):
        self._targets = fed_inputs(project, routes)
        self._actions = sorted(actions, key=lambda a: a.t)  # stable: two at one time keep their order
        self._reported = 0  # the actions whose taking effect is recorded
        # The tunable parameters any action sets, (node, name): each is sent to its node again,
        # as in force there, after a rollback to a checkpoint.
        self.tuned = {tuple(a.parameter.split(".", 1)) for a in self._actions if a.parameter is not None}

    def __bool__(self) -> bool:
        return bool(self._actions)

    def target(self, name: str) -> tuple[str, int, Port] | None:
        """Node, input index and port of an input a scenario may override, or None."""
        found = self._targets.get(name)
        return None if found is None else (found.node, found.index, found.port)

    def add(self, action: ScenarioAction) -> None:
        """An action from a caller, at the time the run stands at: after every action at or before
        it, before the project's later ones."""
        at = next((i for i, a in enumerate(self._actions) if a.t > action.t), len(self._actions))
        self._actions.insert(at, action)
        if action.parameter is not None:
            self.tuned.add(tuple(action.parameter.split(".", 1)))

    def pins_at(self, t: float) -> dict[str, list[tuple[int, Any]]]:
        """The overridden inputs at time ``t``: node → [(input index, value)]."""
        held: dict[str, tuple[Target, Any]] = {}
        tol = _AT * max(1.0, abs(t))
        for action in self._actions:
            if action.t > t + tol:
                break
            if action.parameter is not None:
                continue
            target = self._targets[action.target]
            if action.release is not None:
                held.pop(action.target, None)
            elif action.ramp is not None:
                ramp = action.ramp
                begin = ramp.start if ramp.start is not None else (
                    held[action.target][1] if action.target in held else target.port.start_value())
                share = min(1.0, max(0.0, (t - action.t) / ramp.duration))
                held[action.target] = (target, float(begin + (ramp.to - begin) * share))
            else:
                value = action.value
                held[action.target] = (target, float(value) if target.port.type is PortType.REAL and
                                       target.port.shape is None else value)
        pins: dict[str, list[tuple[int, Any]]] = {}
        for target, value in held.values():
            pins.setdefault(target.node, []).append((target.index, value))
        return pins

    def taking_effect(self, step: int, t: float) -> list[dict[str, Any]]:
        """The record of each action that takes effect at point ``step`` (its time reached), once."""
        tol = _AT * max(1.0, abs(t))
        entries = []
        while self._reported < len(self._actions) and self._actions[self._reported].t <= t + tol:
            action = self._actions[self._reported]
            entry: dict[str, Any] = {"scenario": action.kind, "target": action.target, "t_action": action.t,
                                     "t": t, "step": step}
            if action.value is not None:
                entry["value"] = action.value
            if action.ramp is not None:
                entry["ramp"] = action.ramp.model_dump(by_alias=True, exclude_none=True)
            entries.append(entry)
            self._reported += 1
        return entries

    def parameters_at(self, t: float) -> dict[tuple[str, str], Any]:
        """The parameters the actions at or before ``t`` set, (node, name) → the latest value."""
        tol = _AT * max(1.0, abs(t))
        return {tuple(a.parameter.split(".", 1)): a.value for a in self._actions
                if a.parameter is not None and a.t <= t + tol}

    def tunes(self, t: float, start: dict[str, dict[str, Any]],
              holding: dict[tuple[str, str], Any] | None) -> tuple[dict[str, dict[str, Any]], dict[tuple[str, str], Any]]:
        """The tuned parameters to send at ``t``, by node, and what the nodes hold then: the value
        in force (the latest action's, else the start value, ``start``) of each whose value the
        node does not hold (``holding``; None: the start values, as at the run's start)."""
        if holding is None:
            holding = {(node, name): start.get(node, {}).get(name) for node, name in self.tuned}
        now = {key: start.get(key[0], {}).get(key[1]) for key in self.tuned}
        now.update(self.parameters_at(t))
        changed: dict[str, dict[str, Any]] = {}
        for (node, name), value in now.items():
            held = holding.get((node, name), _UNSET)
            if value is not None and (held != value or type(held) is not type(value)):
                changed.setdefault(node, {})[name] = value
        return changed, {**holding, **{(n, name): v for n, vs in changed.items() for name, v in vs.items()}}

    def parameter_problem(self, tunable: dict[str, dict[str, Any]]) -> str | None:
        """The first parameter action its node cannot take, given each node's tunable parameters
        and their start values (``tunable``, from the nodes' HELLOs), or None."""
        from hycosim.core.frames import fits_tunable

        for a in self._actions:
            if a.parameter is None:
                continue
            node, name = a.parameter.split(".", 1)
            theirs = tunable.get(node, {})
            if name not in theirs:
                return (f"the scenario's action at t = {a.t:g} sets {a.parameter}, which node {node!r} does not "
                        f"declare tunable (its tunable parameters: {', '.join(sorted(theirs)) or 'none'})")
            if not fits_tunable(a.value, theirs[name]):
                return (f"the scenario's action at t = {a.t:g} sets {a.parameter} to {a.value!r}, and it is a "
                        f"{type(theirs[name]).__name__}")
        return None

    def rewind(self, t: float) -> None:
        """Back at a checkpoint at ``t``: the actions from its point on take effect (and are
        recorded) again. Those at the point itself too: a point's checkpoint is taken before
        its actions are recorded, so the record the rollback kept ends before them."""
        tol = _AT * max(1.0, abs(t))
        self._reported = sum(1 for a in self._actions if a.t <= t - tol)
