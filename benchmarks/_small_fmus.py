"""Build the in-process benchmark's three FMI 2.0 co-simulation FMUs (benchmarks/_small_fmus.c)
and the SSP package that couples them:

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

# name → (model number in the C source, [(variable, causality, start)])
MODELS = {
    "Dahlquist": (1, [("k", "parameter", 1.0), ("x", "output", 1.0)]),
    "Feedthrough": (2, [("u", "input", 0.0), ("y", "output", None)]),
    "VanDerPol": (3, [("mu", "parameter", 1.0), ("x0", "output", 2.0), ("x1", "output", 0.0)]),
}


def model_description(name: str) -> str:
    number, variables = MODELS[name]
    rows, outputs = [], []
    for vr, (var, causality, start) in enumerate(variables):
        if causality == "parameter":
            attrs = 'causality="parameter" variability="fixed" initial="exact"'
        elif causality == "input":
            attrs = 'causality="input"'
        else:
            attrs = 'causality="output" ' + ('initial="exact"' if start is not None else 'initial="calculated"')
            # y = u at once: the Feedthrough's output depends on its input.
            deps = "1" if name == "Feedthrough" else ""
            outputs.append(f'      <Unknown index="{vr + 1}" dependencies="{deps}"/>')
        value = f'<Real start="{start!r}"/>' if start is not None else "<Real/>"
        rows.append(f'    <ScalarVariable name="{var}" valueReference="{vr}" {attrs}>{value}</ScalarVariable>')
    initial = "" if name != "Feedthrough" else '    <InitialUnknowns>\n      <Unknown index="2" dependencies="1"/>\n    </InitialUnknowns>\n'
    nl = "\n"
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
{initial}  </ModelStructure>
</fmiModelDescription>
"""


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
    from hycosim.fmu_bridge.ssp import write_ssp

    fmus = build(out_dir)
    config = out_dir / "small3.json"
    config.write_text(json.dumps(project(fmus, steps)))
    return config, write_ssp(load_project(config), out_dir / "small3.ssp")


if __name__ == "__main__":
    print(*write_package(Path(sys.argv[1] if len(sys.argv) > 1 else "."), 400))
