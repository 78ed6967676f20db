"""Model Exchange test FMUs built from tests/c: a bouncing ball (FMI 2.0 ME, FMI 2.0 with both
interfaces, FMI 3.0 ME, FMI 1.0 ME) and a stiff Van der Pol oscillator (FMI 2.0 ME). For the tests and the
FMU overhead benchmark; gcc compiles them."""

from __future__ import annotations

import subprocess
import uuid
import zipfile
from pathlib import Path

C_SOURCES = Path(__file__).resolve().parent / "c"
FMI_HEADERS = Path(__import__("fmpy").__file__).parent / "c-code"

_VARIABLES = """
  <ModelVariables>
    <ScalarVariable name="h" valueReference="0" causality="output" variability="continuous" initial="exact">
      <Real start="1"/></ScalarVariable>
    <ScalarVariable name="der(h)" valueReference="1" causality="local" variability="continuous">
      <Real derivative="1"/></ScalarVariable>
    <ScalarVariable name="v" valueReference="2" causality="output" variability="continuous" initial="exact">
      <Real start="0"/></ScalarVariable>
    <ScalarVariable name="der(v)" valueReference="3" causality="local" variability="continuous">
      <Real derivative="3"/></ScalarVariable>
    <ScalarVariable name="g" valueReference="4" causality="parameter" variability="fixed" initial="exact">
      <Real start="9.81"/></ScalarVariable>
    <ScalarVariable name="e" valueReference="5" causality="parameter" variability="tunable" initial="exact">
      <Real start="0.7"/></ScalarVariable>
    <ScalarVariable name="a" valueReference="6" causality="input" variability="continuous">
      <Real start="0"/></ScalarVariable>
    <ScalarVariable name="kick_at" valueReference="7" causality="parameter" variability="fixed" initial="exact">
      <Real start="-1"/></ScalarVariable>
    <ScalarVariable name="kick" valueReference="8" causality="parameter" variability="fixed" initial="exact">
      <Real start="0"/></ScalarVariable>
    <ScalarVariable name="steps" valueReference="9" causality="local" variability="continuous" initial="exact">
      <Real start="0"/></ScalarVariable>
    <ScalarVariable name="bounces" valueReference="0" causality="output" variability="discrete" initial="exact">
      <Integer start="0"/></ScalarVariable>
    <ScalarVariable name="max_bounces" valueReference="1" causality="parameter" variability="fixed" initial="exact">
      <Integer start="1000000"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="1"/><Unknown index="3"/><Unknown index="11"/></Outputs>
    <Derivatives><Unknown index="2"/><Unknown index="4"/></Derivatives>
  </ModelStructure>
"""
_CAPS = 'modelIdentifier="ball" canGetAndSetFMUstate="true" canSerializeFMUstate="true"'
_ME = f'<ModelExchange {_CAPS} completedIntegratorStepNotNeeded="false"/>'
_CS = f'<CoSimulation {_CAPS} canHandleVariableCommunicationStepSize="true"/>'


_FMI3 = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="Ball" instantiationToken="{{{token}}}">
  <ModelExchange modelIdentifier="ball3" canGetAndSetFMUState="true" canSerializeFMUState="true"
                 needsCompletedIntegratorStep="true"/>
  <ModelVariables>
    <Float64 name="time" valueReference="999" causality="independent" variability="continuous"/>
    <Float64 name="h" valueReference="0" causality="output" variability="continuous" initial="exact" start="1"/>
    <Float64 name="der(h)" valueReference="1" causality="local" variability="continuous" derivative="0"/>
    <Float64 name="v" valueReference="2" causality="output" variability="continuous" initial="exact" start="0"/>
    <Float64 name="der(v)" valueReference="3" causality="local" variability="continuous" derivative="2"/>
    <Float64 name="g" valueReference="4" causality="parameter" variability="fixed" start="9.81"/>
    <Float64 name="e" valueReference="5" causality="parameter" variability="tunable" start="0.7"/>
    <Float64 name="a" valueReference="6" causality="input" variability="continuous" start="0"/>
    <Float64 name="kick_at" valueReference="7" causality="parameter" variability="fixed" start="-1"/>
    <Float64 name="kick" valueReference="8" causality="parameter" variability="fixed" start="0"/>
    <Float64 name="z" valueReference="12" causality="local" variability="continuous"/>
    <Int32 name="bounces" valueReference="10" causality="output" variability="discrete" initial="exact" start="0"/>
    <Int32 name="max_bounces" valueReference="11" causality="parameter" variability="fixed" start="1000000"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="0"/><Output valueReference="2"/><Output valueReference="10"/>
    <ContinuousStateDerivative valueReference="1"/><ContinuousStateDerivative valueReference="3"/>
    <EventIndicator valueReference="12"/>
  </ModelStructure>
</fmiModelDescription>
"""


_VDP = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="VanDerPol" guid="{{{token}}}" numberOfEventIndicators="0">
  <ModelExchange modelIdentifier="vdp"/>
  <ModelVariables>
    <ScalarVariable name="x0" valueReference="0" causality="output" variability="continuous" initial="exact">
      <Real start="2"/></ScalarVariable>
    <ScalarVariable name="der(x0)" valueReference="1" causality="local" variability="continuous">
      <Real derivative="1"/></ScalarVariable>
    <ScalarVariable name="x1" valueReference="2" causality="output" variability="continuous" initial="exact">
      <Real start="0"/></ScalarVariable>
    <ScalarVariable name="der(x1)" valueReference="3" causality="local" variability="continuous">
      <Real derivative="3"/></ScalarVariable>
    <ScalarVariable name="mu" valueReference="4" causality="parameter" variability="fixed" initial="exact">
      <Real start="1000"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="1"/><Unknown index="3"/></Outputs>
    <Derivatives><Unknown index="2"/><Unknown index="4"/></Derivatives>
  </ModelStructure>
</fmiModelDescription>
"""


_FMI1 = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="1.0" modelName="Ball" modelIdentifier="ball1" guid="{{{token}}}"
  numberOfContinuousStates="2" numberOfEventIndicators="1">
  <ModelVariables>
    <ScalarVariable name="h" valueReference="0" causality="output"><Real start="1" fixed="true"/></ScalarVariable>
    <ScalarVariable name="v" valueReference="2" causality="output"><Real start="0" fixed="true"/></ScalarVariable>
    <ScalarVariable name="g" valueReference="4" variability="parameter" causality="internal">
      <Real start="9.81" fixed="true"/></ScalarVariable>
    <ScalarVariable name="e" valueReference="5" variability="parameter" causality="internal">
      <Real start="0.7" fixed="true"/></ScalarVariable>
    <ScalarVariable name="a" valueReference="6" causality="input"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="kick_at" valueReference="7" variability="parameter" causality="internal">
      <Real start="-1" fixed="true"/></ScalarVariable>
    <ScalarVariable name="kick" valueReference="8" variability="parameter" causality="internal">
      <Real start="0" fixed="true"/></ScalarVariable>
    <ScalarVariable name="bounces" valueReference="0" variability="discrete" causality="output">
      <Integer start="0" fixed="true"/></ScalarVariable>
  </ModelVariables>
</fmiModelDescription>
"""


def _fmu(out: Path, so: Path, name: str, interfaces: str) -> Path:
    xml = (f'<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription fmiVersion="2.0" modelName="Ball" '
           f'guid="{{{uuid.uuid4()}}}" numberOfEventIndicators="1">\n  {interfaces}\n{_VARIABLES}'
           '</fmiModelDescription>\n')
    return _zip(out / f"{name}.fmu", xml, so, "linux64")


def _compile(source: str, so: Path, *flags: str) -> None:
    subprocess.run(["gcc", "-shared", "-fPIC", "-O1", "-Wall", "-Werror", "-Wno-unused-parameter", *flags,
                    "-o", str(so), str(C_SOURCES / source)], check=True, capture_output=True)


def _zip(path: Path, xml: str, so: Path, platform: str) -> Path:
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("modelDescription.xml", xml)
        z.write(so, f"binaries/{platform}/{so.name}")
    return path


def build_me_fmus(out: Path) -> dict[str, Path]:
    """Compile and package the test FMUs into ``out``: me, both, me3, me1 (balls), vdp."""
    _compile("ball_me2.c", out / "ball.so", f"-I{FMI_HEADERS}")
    _compile("ball_me3.c", out / "ball3.so", "-fvisibility=hidden")
    _compile("vdp_me2.c", out / "vdp.so", f"-I{FMI_HEADERS}")
    _compile("ball_me1.c", out / "ball1.so", f"-I{FMI_HEADERS}", "-fvisibility=hidden")
    return {"me": _fmu(out, out / "ball.so", "BallME", _ME),
            "both": _fmu(out, out / "ball.so", "BallBoth", _ME + "\n  " + _CS),
            "me3": _zip(out / "BallME3.fmu", _FMI3.format(token=uuid.uuid4()), out / "ball3.so", "x86_64-linux"),
            "vdp": _zip(out / "VanDerPol.fmu", _VDP.format(token=uuid.uuid4()), out / "vdp.so", "linux64"),
            "me1": _zip(out / "BallME1.fmu", _FMI1.format(token=uuid.uuid4()), out / "ball1.so", "linux64")}
