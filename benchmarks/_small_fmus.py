"""Build the small FMI 2.0 co-simulation FMUs of benchmarks/_small_fmus.c (and their FMI 1.0
builds, benchmarks/_small_fmus1.c) (the in-process
benchmark's three, and the cross-check's typed feedthrough and bouncing ball) and the SSP
package the in-process benchmark runs:

    Dahlquist.x --(factor 2, offset 1)--> Feedthrough.u,   VanDerPol on its own,

the system ECOS runs in one process in the issue that asked for the in-process mode. The
package carries hycosim's macro step in an annotation; ECOS is given the same step.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tests import this as benchmarks._small_fmus

from _fmu_build import native_fmu  # noqa: E402

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "_small_fmus.c"
SOURCE1 = HERE / "_small_fmus1.c"  # the same models as FMI 1.0 co-simulation FMUs

# name → (model number in the C source, [(variable, causality, type, start, dependencies)]):
# an output's dependencies are the inputs it reads at once (None: not an output). A start of
# None is calculated (the model gives it at initialisation).
MODELS = {
    "Dahlquist": (1, [("k", "parameter", "Real", 1.0, None), ("x", "output", "Real", 1.0, [])]),
    "Feedthrough": (2, [("u", "input", "Real", 0.0, None), ("y", "output", "Real", None, ["u"])]),
    "VanDerPol": (3, [("mu", "parameter", "Real", 1.0, None), ("x0", "output", "Real", 2.0, []),
                      ("x1", "output", "Real", 0.0, [])]),
    "Types": (4, [("gain", "parameter", "Real", 1.0, None), ("ru", "input", "Real", 0.0, None),
                  ("ry", "output", "Real", None, ["ru"]), ("offset", "parameter", "Integer", 0, None),
                  ("iu", "input", "Integer", 0, None), ("iy", "output", "Integer", None, ["iu"]),
                  ("bu", "input", "Boolean", False, None), ("by", "output", "Boolean", None, ["bu"])]),
    "Ball": (5, [("h", "output", "Real", 1.0, []), ("v", "output", "Real", 0.0, []),
                 ("g", "parameter", "Real", 9.81, None), ("e", "parameter", "Real", 0.8, None),
                 ("bounces", "output", "Integer", 0, []), ("falling", "output", "Boolean", None, [])]),
    "Constant": (6, [("y", "output", "Real", 3.0, [])]),
    "LateFeedthrough": (7, [("u", "input", "Real", 0.0, None), ("y", "output", "Real", None, ["u"])]),
}
# Models whose outputs change only when they leave initialisation mode and in their steps,
# never when an input is set: an engine reads y(t) = u(t - H), as hycosim records any output.
LATE = {"LateFeedthrough"}
# Value references: each type's variables in order from its first (benchmarks/_small_fmus.c).
_FIRST_VR = {"Real": 0, "Integer": 100, "Boolean": 200}


def _start(type_: str, start: object) -> str:
    if start is None:
        return ""
    return f' start="{str(start).lower()}"' if type_ == "Boolean" else f' start="{start!r}"'


def model_description(name: str) -> str:
    """The modelDescription.xml of small FMU ``name``: its variables, outputs and initial unknowns with
    their dependencies."""
    number, variables = MODELS[name]
    rows, outputs, initial = [], [], []
    index = {var: i + 1 for i, (var, *_) in enumerate(variables)}
    counts = dict.fromkeys(_FIRST_VR, 0)
    for var, causality, type_, start, deps in variables:
        vr = _FIRST_VR[type_] + counts[type_]
        counts[type_] += 1
        if causality == "parameter":
            attrs = 'causality="parameter" variability="fixed" initial="exact"'
        elif causality == "input":
            attrs = 'causality="input"' + (' variability="discrete"' if type_ != "Real" else "")
        else:
            attrs = ('causality="output" ' + (' variability="discrete" ' if type_ != "Real" else "")
                     + ('initial="exact"' if start is not None else 'initial="calculated"'))
            unknown = f'      <Unknown index="{index[var]}" dependencies="{" ".join(str(index[d]) for d in deps)}"/>'
            outputs.append(unknown)
            if start is None:  # FMI 2 lists a calculated output among the initial unknowns
                initial.append(unknown)
        rows.append(f'    <ScalarVariable name="{var}" valueReference="{vr}" {attrs}>'
                    f'<{type_}{_start(type_, start)}/></ScalarVariable>')
    nl = "\n"
    initial_block = f"    <InitialUnknowns>{nl}{nl.join(initial)}{nl}    </InitialUnknowns>{nl}" if initial else ""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{name}" guid="{{hycosim-small-{number}}}"
  generationTool="hycosim benchmarks" variableNamingConvention="flat" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{name}" canHandleVariableCommunicationStepSize="true"
    canGetAndSetFMUstate="true"/>
  <DefaultExperiment startTime="0" stopTime="4" stepSize="0.01"/>
  <ModelVariables>
{nl.join(rows)}
  </ModelVariables>
  <ModelStructure>
    <Outputs>
{nl.join(outputs)}
    </Outputs>
{initial_block}  </ModelStructure>
</fmiModelDescription>
"""


def model_description1(name: str) -> str:
    """The FMI 1.0 co-simulation model description of one model (benchmarks/_small_fmus1.c)."""
    number, variables = MODELS[name]
    rows = []
    counts = dict.fromkeys(_FIRST_VR, 0)
    for var, causality, type_, start, _ in variables:
        vr = _FIRST_VR[type_] + counts[type_]
        counts[type_] += 1
        discrete = ' variability="discrete"' if type_ != "Real" else ""
        if causality == "parameter":
            attrs, fixed = 'variability="parameter" causality="internal"', ' fixed="true"'
        else:
            attrs, fixed = f'causality="{causality}"{discrete}', ""
        rows.append(f'    <ScalarVariable name="{var}" valueReference="{vr}" {attrs}>'
                    f'<{type_}{_start(type_, start)}{fixed if start is not None else ""}/></ScalarVariable>')
    nl = "\n"
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="1.0" modelName="{name}" modelIdentifier="{name}" guid="{{hycosim-small1-{number}}}"
  generationTool="hycosim benchmarks" variableNamingConvention="flat" numberOfContinuousStates="0"
  numberOfEventIndicators="0">
  <DefaultExperiment startTime="0" stopTime="4"/>
  <ModelVariables>
{nl.join(rows)}
  </ModelVariables>
  <Implementation>
    <CoSimulation_StandAlone>
      <Capabilities canHandleVariableCommunicationStepSize="true" canHandleEvents="true"
        canRejectSteps="false" canInterpolateInputs="false" maxOutputDerivativeOrder="0"
        canRunAsynchronuously="false" canSignalEvents="false" canBeInstantiatedOnlyOncePerProcess="false"
        canNotUseMemoryManagementFunctions="true"/>
    </CoSimulation_StandAlone>
  </Implementation>
</fmiModelDescription>
"""


def build1(out_dir: Path) -> dict[str, Path]:
    """Compile each model as an FMI 1.0 co-simulation FMU, ``out_dir/<Name>.fmu``."""
    return {name: native_fmu(SOURCE1, name, model_description1(name), out_dir / f"{name}.fmu",
                             ["-Wall", "-Wno-unused-parameter", "-Werror", f"-DMODEL={number}",
                              f"-DMODEL_IDENTIFIER={name}"])
            for name, (number, _) in MODELS.items()}


def build(out_dir: Path) -> dict[str, Path]:
    """Compile each model and zip it with its model description as ``out_dir/<Name>.fmu``."""
    return {name: native_fmu(SOURCE, name, model_description(name), out_dir / f"{name}.fmu",
                             ["-Wall", "-Wno-unused-parameter", "-Werror", f"-DMODEL={number}"])
            for name, (number, _) in MODELS.items()}


def project(fmus: dict[str, Path], steps: int, step_size: float = 0.01) -> dict:
    """The hycosim project of the three FMUs (``steps`` macro steps of ``step_size``)."""
    nodes = [
        {"nodeName": "dahlquist", "UID": 1, "fmu": str(fmus["Dahlquist"]), "input": [], "output": ["x"]},
        {"nodeName": "ft", "UID": 2, "fmu": str(fmus["Feedthrough"]), "input": ["u"], "output": ["y"]},
        {"nodeName": "vdp", "UID": 3, "fmu": str(fmus["VanDerPol"]), "input": [], "output": ["x0", "x1"]},
    ]
    links = [{"from": "dahlquist.x", "to": "ft.u", "factor": 2.0, "offset": 1.0}]
    return {"projectName": "small3", "serverIP": "127.0.0.1:7447", "nodeNum": 3, "nodeLists": nodes,
            "linkNum": 1, "linkLists": links,
            "coSimulation": {"stepSize": step_size, "stopTime": round(steps * step_size, 12), "stepTimeout": 30.0}}


def write_package(out_dir: Path, steps: int) -> tuple[Path, Path]:
    """Build the FMUs into ``out_dir`` and write the project (``small3.json``) and its SSP
    package (``small3.ssp``, through hycosim's SSP export); return both paths."""
    from hycosim.core.config import load_project
    from hycosim.fmi.ssp import write_ssp

    fmus = build(out_dir)
    config = out_dir / "small3.json"
    config.write_text(json.dumps(project(fmus, steps)))
    return config, write_ssp(load_project(config), out_dir / "small3.ssp")


if __name__ == "__main__":
    print(*write_package(Path(sys.argv[1] if len(sys.argv) > 1 else "."), 400))


def osp_structure(fmus: dict[str, Path], folder: Path, steps: int, h: float) -> Path:
    """An OSP system structure of the small FMUs (copied into ``folder`` beside it), for the
    cross-check against libcosim: initial values of each type an FMU here has (Real, Integer,
    Boolean), a multi-rate simulator (the ball, every second step), a linear transformation and
    an algebraic loop of two feedthroughs (one through a transformation), a power bond (two
    feedthroughs feeding each other), a sum of one signal.
    Return the path of ``folder/OspSystemStructure.xml``."""
    import shutil

    folder.mkdir(parents=True, exist_ok=True)
    for name in ("Dahlquist", "Feedthrough", "Types", "Ball"):
        shutil.copy(fmus[name], folder / f"{name}.fmu")
    stop = round(steps * h, 12)
    xml = f"""<?xml version="1.0" encoding="UTF-8"?>
<OspSystemStructure xmlns="http://opensimulationplatform.com/MSMI/OSPSystemStructure" version="0.1">
  <StartTime>0.0</StartTime>
  <EndTime>{stop!r}</EndTime>
  <BaseStepSize>{h!r}</BaseStepSize>
  <Algorithm>fixedStep</Algorithm>
  <Simulators>
    <Simulator name="dahlquist" source="Dahlquist.fmu">
      <InitialValues><InitialValue variable="k"><Real value="2.0"/></InitialValue></InitialValues>
    </Simulator>
    <Simulator name="ft" source="Feedthrough.fmu"/>
    <Simulator name="loopA" source="Feedthrough.fmu"/>
    <Simulator name="loopB" source="Feedthrough.fmu"/>
    <Simulator name="height" source="Feedthrough.fmu"/>
    <Simulator name="bondA" source="Feedthrough.fmu"/>
    <Simulator name="bondB" source="Feedthrough.fmu"/>
    <Simulator name="types" source="Types.fmu">
      <InitialValues>
        <InitialValue variable="gain"><Real value="3.0"/></InitialValue>
        <InitialValue variable="offset"><Integer value="5"/></InitialValue>
        <InitialValue variable="bu"><Boolean value="true"/></InitialValue>
      </InitialValues>
    </Simulator>
    <Simulator name="ball" source="Ball.fmu" stepSize="{2 * h!r}">
      <InitialValues><InitialValue variable="e"><Real value="0.7"/></InitialValue></InitialValues>
    </Simulator>
  </Simulators>
  <Functions>
    <LinearTransformation name="twice" factor="2.0" offset="1.0"/>
    <LinearTransformation name="half" factor="0.5" offset="1.0"/>
    <Sum name="one" inputCount="1"/>
  </Functions>
  <Connections>
    <SignalConnection><Variable simulator="dahlquist" name="x"/><Signal function="twice" name="in"/></SignalConnection>
    <SignalConnection><Variable simulator="ft" name="u"/><Signal function="twice" name="out"/></SignalConnection>
    <VariableConnection><Variable simulator="ft" name="y"/><Variable simulator="types" name="ru"/></VariableConnection>
    <VariableConnection><Variable simulator="types" name="iu"/><Variable simulator="ball" name="bounces"/></VariableConnection>
    <VariableConnection><Variable simulator="loopA" name="y"/><Variable simulator="loopB" name="u"/></VariableConnection>
    <VariableConnection powerBond="bond"><Variable simulator="bondA" name="y" causality="output"/>
      <Variable simulator="bondB" name="u" causality="input"/></VariableConnection>
    <VariableConnection powerBond="bond"><Variable simulator="bondB" name="y" causality="output"/>
      <Variable simulator="bondA" name="u" causality="input"/></VariableConnection>
    <SignalConnection><Variable simulator="loopB" name="y"/><Signal function="half" name="in"/></SignalConnection>
    <SignalConnection><Variable simulator="loopA" name="u"/><Signal function="half" name="out"/></SignalConnection>
    <VariableConnection><Variable simulator="ball" name="falling"/><Variable simulator="types" name="bu"/></VariableConnection>
    <SignalConnection><Variable simulator="ball" name="h"/><Signal function="one" name="in[0]"/></SignalConnection>
    <SignalConnection><Variable simulator="height" name="u"/><Signal function="one" name="out"/></SignalConnection>
  </Connections>
</OspSystemStructure>
"""
    path = folder / "OspSystemStructure.xml"
    path.write_text(xml)
    return path
