"""FMI 3.0 co-simulation test FMUs with what FMI 3 added: array variables whose sizes are
structural parameters (tests/c/statespace3.c, a linear state-space model), and the same model
described with clocks (periodic and triggered) and as scheduled execution only. gcc compiles
them."""

from __future__ import annotations

import uuid
from pathlib import Path

from tests.me_fmus import _compile, _zip

M, N, R = 2, 3, 3  # the default sizes, as statespace3.c sets them


def _defaults(m: int, n: int, r: int) -> dict[str, list[float]]:
    """The start values of every array at sizes m, n, r, row-major: statespace3.c's defaults()."""
    A = [-(i + 1.0) if i == j else (0.5 if j == i + 1 else 0.0) for i in range(n) for j in range(n)]
    B = [1.0 if k == i % m else 0.0 for i in range(n) for k in range(m)]
    C = [1.0 if l == i % r else (0.25 if i == 0 else 0.0) for l in range(r) for i in range(n)]
    D = [0.1 if l == k else 0.0 for l in range(r) for k in range(m)]
    return {"A": A, "B": B, "C": C, "D": D, "x0": [1.0 / (i + 1) for i in range(n)], "u": [0.0] * m}


def _starts(values: list[float]) -> str:
    return " ".join(repr(v) for v in values)


CLOCKS = {
    "periodic": '<Clock name="tick" valueReference="20" causality="input" intervalVariability="constant" '
                'intervalDecimal="0.1"/>',
    "triggered": '<Clock name="tick" valueReference="20" causality="input" intervalVariability="constant" '
                 'intervalDecimal="0.1"/>\n    <Clock name="trip" valueReference="21" causality="output" '
                 'intervalVariability="triggered"/>',
    "shifted": '<Clock name="tick" valueReference="20" causality="input" intervalVariability="constant" '
               'intervalCounter="1" resolution="10" shiftDecimal="0.05"/>',
    "tunable": '<Clock name="tick" valueReference="20" causality="input" intervalVariability="tunable" '
               'intervalDecimal="0.1"/>',
}


# The clocked partition of tests/c/statespace3.c: outputs on the clock tick (vr 20).
_CLOCKED = ('<Float64 name="held" valueReference="23" causality="output" variability="discrete" clocks="20"/>\n'
            '    <Float64 name="ticks" valueReference="24" causality="output" variability="discrete" clocks="20"/>')


def model_description(clocks: str = "", interface: str | None = None, event_mode: bool = True) -> str:
    """The state-space FMU's description at its default sizes; ``clocks`` (a key of CLOCKS)
    adds clock variables (with the clocked outputs held and ticks, and event mode unless not
    ``event_mode``), ``interface`` replaces the co-simulation element."""
    d = _defaults(M, N, R)
    events = ' hasEventMode="true"' if clocks and event_mode else ""
    caps = ('<CoSimulation modelIdentifier="statespace3" canHandleVariableCommunicationStepSize="true" '
            f'canGetAndSetFMUState="true" canSerializeFMUState="true"{events}/>')
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="StateSpace" instantiationToken="{{{uuid.uuid4()}}}">
  {interface or caps}
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <UInt64 name="m" valueReference="1" causality="structuralParameter" variability="fixed" start="{M}"/>
    <UInt64 name="n" valueReference="2" causality="structuralParameter" variability="fixed" start="{N}"/>
    <UInt64 name="r" valueReference="3" causality="structuralParameter" variability="fixed" start="{R}"/>
    <Float64 name="A" valueReference="4" causality="parameter" variability="tunable" start="{_starts(d['A'])}">
      <Dimension valueReference="2"/><Dimension valueReference="2"/></Float64>
    <Float64 name="B" valueReference="5" causality="parameter" variability="tunable" start="{_starts(d['B'])}">
      <Dimension valueReference="2"/><Dimension valueReference="1"/></Float64>
    <Float64 name="C" valueReference="6" causality="parameter" variability="tunable" start="{_starts(d['C'])}">
      <Dimension valueReference="3"/><Dimension valueReference="2"/></Float64>
    <Float64 name="D" valueReference="7" causality="parameter" variability="tunable" start="{_starts(d['D'])}">
      <Dimension valueReference="3"/><Dimension valueReference="1"/></Float64>
    <Float64 name="x0" valueReference="8" causality="parameter" variability="fixed" start="{_starts(d['x0'])}">
      <Dimension valueReference="2"/></Float64>
    <Float64 name="u" valueReference="9" causality="input" variability="continuous" start="{_starts(d['u'])}">
      <Dimension valueReference="1"/></Float64>
    <Float64 name="y" valueReference="10" causality="output" variability="continuous">
      <Dimension valueReference="3"/></Float64>
    <Float64 name="x" valueReference="11" causality="local" variability="continuous">
      <Dimension valueReference="2"/></Float64>
    <Float64 name="g" valueReference="12" causality="input" variability="continuous" start="0"/>
    <Float64 name="s" valueReference="13" causality="output" variability="continuous"/>
    <Float64 name="pair" valueReference="14" causality="output" variability="continuous">
      <Dimension start="2"/></Float64>
    <String name="label" valueReference="15" causality="input" variability="discrete"><Start value=""/></String>
    <String name="greeting" valueReference="16" causality="output" variability="discrete"/>
    <Binary name="blob" valueReference="17" causality="input" variability="discrete"><Start value=""/></Binary>
    <Binary name="blob_out" valueReference="18" causality="output" variability="discrete"/>
    <Float32 name="k32" valueReference="22" causality="input" variability="continuous" start="0"/>
    <Float32 name="s32" valueReference="19" causality="output" variability="continuous"/>
    {CLOCKS.get(clocks, "")}
    {_CLOCKED if clocks else ""}
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="10" dependencies="9"/>
    <Output valueReference="13" dependencies="9"/>
    <Output valueReference="14"/>
    <Output valueReference="16" dependencies="15"/>
    <Output valueReference="18" dependencies="17"/>
    <Output valueReference="19" dependencies="9 22"/>
    {'<Output valueReference="23"/><Output valueReference="24"/>' if clocks else ""}
  </ModelStructure>
</fmiModelDescription>
"""


def build(out: Path) -> dict[str, Path]:
    """Compile statespace3.c and package it into ``out``: statespace (arrays); periodic,
    shifted, triggered and tunable (the same with the clocks of CLOCKS); no-event-mode (a
    periodic clock without event mode); model-exchange (a periodic clock, Model Exchange only);
    scheduled (scheduled execution only)."""
    out.mkdir(parents=True, exist_ok=True)
    so = out / "statespace3.so"
    _compile("statespace3.c", so, "-fvisibility=hidden")
    scheduled = '<ScheduledExecution modelIdentifier="statespace3"/>'
    return {"statespace": _zip(out / "StateSpace.fmu", model_description(), so, "x86_64-linux"),
            "periodic": _zip(out / "Periodic.fmu", model_description("periodic"), so, "x86_64-linux"),
            "triggered": _zip(out / "Triggered.fmu", model_description("triggered"), so, "x86_64-linux"),
            "shifted": _zip(out / "Shifted.fmu", model_description("shifted"), so, "x86_64-linux"),
            "tunable": _zip(out / "Tunable.fmu", model_description("tunable"), so, "x86_64-linux"),
            "model-exchange": _zip(out / "ModelExchange.fmu", model_description(
                "periodic", '<ModelExchange modelIdentifier="statespace3"/>'), so, "x86_64-linux"),
            "no-event-mode": _zip(out / "NoEventMode.fmu", model_description("periodic", event_mode=False), so,
                                  "x86_64-linux"),
            "scheduled": _zip(out / "Scheduled.fmu", model_description("periodic", scheduled), so, "x86_64-linux")}
