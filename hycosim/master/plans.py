"""Which of the project's asks a run takes up, given what its stepping nodes said they can do.

Checkpoints, event localisation, iterative coupling, the error-controlled step and interpolated
inputs each need every stepping node to take part (serialise its state, take a step again, take
one of any length, interpolate its inputs). A node says what it can in its HELLO; a node that
said nothing (a bridge FMU through the gateway) can do none of them. Each plan here is taken up
or not, and says in words for the run's metadata which, or why not, naming the nodes that cannot.

``said`` maps each stepping node, in the project's order, to its HELLO's capabilities. They come
off the network: anything but the JSON ``true`` the capability asks for counts as "cannot".
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from hycosim.core.schema import CoSimulation, Iterate, StepControl
from hycosim.master.interpolation import STARTUP_SPLIT

Said = Mapping[str, Mapping[str, Any]]


@dataclass(frozen=True)
class Plan:
    """Whether an ask is taken up, its words for the metadata, and (when not) why, for the log."""

    on: bool
    words: str
    why: str = ""
    # Iterative coupling: the nodes whose inputs follow polynomials over a step, and those that
    # have inputs but hold them (they cannot interpolate).
    interpolated: tuple[str, ...] = ()
    holding: tuple[str, ...] = ()


def cannot_retake(said: Said, variable: bool) -> str:
    """Why steps cannot be taken again (shorter, with ``variable``): the nodes that cannot."""
    fixed = sorted(n for n, c in said.items() if c.get("rollback") is not True)
    why = [f"{', '.join(fixed)} cannot get and set state"] if fixed else []
    if variable:
        rigid = sorted(n for n, c in said.items() if c.get("variableStep") is False)
        if rigid:
            why.append(f"{', '.join(rigid)} cannot take steps of any length")
    return "; ".join(why)


def checkpoints(cosim: CoSimulation, said: Said) -> Plan:
    """Checkpoints every checkpointEvery seconds, if every stepping node can serialise its state."""
    every = cosim.checkpointEvery
    if every is None:
        return Plan(False, "off (no checkpointEvery)")
    fixed = sorted(n for n, c in said.items() if c.get("serialize") is not True)
    if fixed:
        return Plan(False, f"off: {', '.join(fixed)} cannot serialise their state", why=", ".join(fixed))
    return Plan(True, f"every {every:g} s of simulated time")


def localisation(cosim: CoSimulation, said: Said) -> Plan:
    """Steps rolled back and bisected to locate a guard's crossing within eventTolerance."""
    tol = cosim.eventTolerance
    if tol is None:
        return Plan(False, "none: fixed macro steps (no eventTolerance)")
    why = cannot_retake(said, variable=True)
    if why:
        return Plan(False, f"none: fixed macro steps ({why})", why=why)
    return Plan(True, f"rollback and bisection to {tol:g} s")


def iteration(it: Iterate, said: Said, has_inputs: Mapping[str, bool]) -> Plan:
    """Each step taken again until its inputs settle; with ``it.interpolate``, on inputs that
    follow polynomials for the nodes that can interpolate them (``has_inputs``: per node)."""
    why = cannot_retake(said, variable=False)
    if why:
        return Plan(False, f"none: one take of each step ({why})", why=why)
    words = (f"up to {it.maxIterations} takes of each step until the inputs change by at most "
             f"{it.tolerance:g}·max(1, |value|)"
             + (f", relaxation {it.relaxation:g}" if it.relaxation != 1.0 else "")
             + f"; a step that does not converge: {it.onFailure}")
    if it.interpolate == 0:
        return Plan(True, words + "; inputs held at the step's end value")
    takes = tuple(sorted(n for n, c in said.items() if c.get("interpolates") is True))
    holds = tuple(sorted(n for n in said if n not in takes and has_inputs.get(n)))
    held = f"; {', '.join(holds)} cannot interpolate its inputs and holds the step's end value" if holds else ""
    if not takes:
        return Plan(True, words + held, holding=holds)
    degree = it.interpolate
    short = (f"; the first {degree - 1} macro steps taken as {STARTUP_SPLIT} each, until there are "
             f"points enough" if degree > 1 else "")
    return Plan(True, words + f"; inputs of {', '.join(takes)} interpolated over each step by polynomials of "
                f"degree {degree} (FMI input derivatives{short}){held}", interpolated=takes, holding=holds)


def step_control(sc: StepControl, step_size: float, said: Said) -> Plan:
    """Each step's length chosen by the error of holding its inputs, between minStep and maxStep."""
    why = cannot_retake(said, variable=True)
    if why:
        return Plan(False, f"none: fixed macro steps of {step_size:g} s ({why})", why=why)
    return Plan(True, f"steps of {sc.minStep:g} to {sc.maxStep:g} s, each held input's error over a "
                f"step (its change × step / 2) at most {sc.tolerance:g}·max(1, |value|) s")


def direct_steps(stepping: list[str], direct: Mapping[str, Any], *, multirate: bool, played: bool,
                 checkpoints: bool, algorithm: str) -> Plan:
    """Macro steps as calls (a node hosted in process steps when the master calls it, and returns
    its outputs) rather than STEP and OUTPUTS frames: for a run whose every stepping node is hosted
    so, and whose steps need nothing a call does not carry (each node's own rate, a played
    source's samples, a checkpoint's states, or what the master algorithm says needs frames:
    ``algorithm``, its words, e.g. "interpolated inputs" for input slopes)."""
    if not stepping:
        return Plan(False, "frames (no stepping node)")
    why = [w for on, w in ((any(n not in direct for n in stepping), "nodes in processes of their own"),
                           (multirate, "multi-rate"), (played, "played sources"), (checkpoints, "checkpoints"),
                           (bool(algorithm), algorithm)) if on]
    if why:
        return Plan(False, f"frames ({', '.join(why)})", why=", ".join(why))
    return Plan(True, "calls (in process)")
