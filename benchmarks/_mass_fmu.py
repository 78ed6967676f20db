"""Build the accuracy benchmark's mass FMU (benchmarks/_mass_fmu.c: one FMU for every mass of
every reference problem, an instance per mass) for this machine: a native FMI 2.0
co-simulation FMU that can interpolate its inputs (``canInterpolateInputs``), save and
restore its state and serialise it.

Native C rather than pythonfmu: pythonfmu's exported binary answers
``fmi2SetRealInputDerivatives`` with "not supported", and input derivatives are what
iterative coupling with interpolated inputs sends.
"""

from __future__ import annotations

import sys
from pathlib import Path

# Run by the benchmarks from their folder, and imported by the tests as benchmarks._mass_fmu.
sys.path.insert(0, str(Path(__file__).resolve().parent))
from _fmu_build import native_fmu  # noqa: E402

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "_mass_fmu.c"
IDENT = "Mass"
GUID = "{8c4e3f0a-6a55-4d8e-9a4b-5d1f0c2e7a31}"

PARAMETERS = [("m", 1.0), ("k", 10.0), ("c", 0.0), ("kl", 0.0), ("kr", 0.0), ("pulse_at", 0.0),
              ("pulse_width", 1.0), ("pulse", 0.0), ("substeps", 20.0), ("max_dt", 1e-4)]
INPUTS = ["F", "xl", "xr"]
OUTPUTS = ["x", "v", "Fl", "Fr"]
FEEDS = {"Fl": "xl", "Fr": "xr"}  # the outputs an input reaches at once (the spring's force)


def model_description() -> str:
    """The FMU's modelDescription.xml: value references in the C source's order."""
    rows = []
    for vr, (name, start) in enumerate(PARAMETERS):
        rows.append(f'    <ScalarVariable name="{name}" valueReference="{vr}" causality="parameter" '
                    f'variability="fixed" initial="exact"><Real start="{start!r}"/></ScalarVariable>')
    base = len(PARAMETERS)
    for i, name in enumerate(INPUTS):
        rows.append(f'    <ScalarVariable name="{name}" valueReference="{base + i}" causality="input">'
                    f'<Real start="0.0"/></ScalarVariable>')
    base += len(INPUTS)
    for i, name in enumerate(OUTPUTS):
        # x and v are the state: set as start values (a mass displaced at t = 0).
        initial = "exact" if name in ("x", "v") else "calculated"
        start = '<Real start="0.0"/>' if initial == "exact" else "<Real/>"
        rows.append(f'    <ScalarVariable name="{name}" valueReference="{base + i}" causality="output" '
                    f'initial="{initial}">{start}</ScalarVariable>')
    index = {name: i + 1 for i, name in enumerate([p for p, _ in PARAMETERS] + INPUTS + OUTPUTS)}
    unknowns = []
    for name in OUTPUTS:
        feeds = FEEDS.get(name)
        deps = str(index[feeds]) if feeds else ""
        unknowns.append(f'      <Unknown index="{index[name]}" dependencies="{deps}"/>')
    # Fl and Fr are calculated at initialisation, each from the input its spring reads: listed, so
    # that the initialisation phase (and validate) need not take them as reading every input.
    initial = "\n".join(f'      <Unknown index="{index[n]}" dependencies="{index[FEEDS[n]]}"/>'
                        for n in OUTPUTS if n not in ("x", "v"))
    variables, outputs = "\n".join(rows), "\n".join(unknowns)
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Mass" guid="{GUID}" generationTool="hycosim benchmarks"
  description="a mass on a spring and damper, coupled by force or by displacement; inputs interpolated"
  variableNamingConvention="flat" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{IDENT}" canHandleVariableCommunicationStepSize="true"
    canInterpolateInputs="true" maxOutputDerivativeOrder="0" canGetAndSetFMUstate="true"
    canSerializeFMUstate="true"/>
  <ModelVariables>
{variables}
  </ModelVariables>
  <ModelStructure>
    <Outputs>
{outputs}
    </Outputs>
    <InitialUnknowns>
{initial}
    </InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"""


def build(out_dir: Path) -> Path:
    """Compile benchmarks/_mass_fmu.c and zip it with its model description into ``out_dir/Mass.fmu``."""
    return native_fmu(SOURCE, IDENT, model_description(), out_dir / f"{IDENT}.fmu", ["-Wall", "-Wextra", "-Werror"])


if __name__ == "__main__":
    import sys

    print(build(Path(sys.argv[1] if len(sys.argv) > 1 else ".")))
