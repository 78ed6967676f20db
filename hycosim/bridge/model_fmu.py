"""Packaging a Python model class as an FMU (pythonfmu for FMI 2.0, pythonfmu3 for FMI 3.0).

The model script defines one ``pythonfmu.Fmi2Slave`` (or ``pythonfmu3.Fmi3Slave``)
subclass; resources (an MJCF file, a checkpoint) travel in the FMU's ``resources/``.
The same model then runs as a hycosim node (``"fmu": "model.fmu"``) and in plain fmpy.

Two things to know about such FMUs: the importing process needs a Python runtime with
the model's packages (pythonfmu embeds the interpreter it was built with), and pythonfmu
writes no InitialUnknowns unless outputs are registered with ``initial=exact``.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

from hycosim.core.extras import install_hint


class ModelFmuError(RuntimeError):
    """A model script that could not be packaged; names the script."""


def build_model_fmu(script: Path, dest: Path, *, resources: list[Path] | None = None, fmi_version: str = "2.0",
                    can_get_and_set_state: bool = True) -> Path:
    """Build ``dest`` (a folder or a ``.fmu`` path) from the model class in ``script``; return the FMU path.

    ``can_get_and_set_state`` declares fmi2GetFMUstate/SetFMUstate support (pythonfmu saves
    the registered variables), which lets the coordinator roll steps back to locate events,
    and fmi2SerializeFMUstate (pythonfmu writes the saved state as JSON), which lets a run's
    checkpoints hold the FMU's state. A model with state beyond its variables saves it in
    its own ``_get_fmu_state``/``_set_fmu_state``.
    """
    script = Path(script)
    if not script.is_file():
        raise ModelFmuError(f"{script}: no such model script")
    module, flag = ("pythonfmu3", "FMUState") if fmi_version.startswith("3") else ("pythonfmu", "FMUstate")
    if importlib.util.find_spec(module) is None:
        raise ModelFmuError(f"{script}: packaging as FMI {fmi_version} needs {module}, in hycosim's [models] extra: "
                            f"{install_hint('models')}")
    job = {"script": str(script.resolve()), "dest": str(Path(dest).resolve()),
           "resources": [str(Path(r).resolve()) for r in resources or []],
           "flags": {f"canGetAndSet{flag}": can_get_and_set_state, f"canSerialize{flag}": can_get_and_set_state}}
    # In a fresh interpreter: a process that has loaded a pythonfmu FMU has imported the copy of
    # pythonfmu inside that FMU's resources, which lacks the binaries the builder packs, and
    # would build FMUs without them.
    try:
        res = subprocess.run([sys.executable, "-P", "-c", _BUILD.format(module=module), json.dumps(job)],
                             capture_output=True, text=True, timeout=600)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise ModelFmuError(f"{script}: packaging as FMI {fmi_version} failed: {exc}") from None
    if res.returncode:
        why = (res.stderr.strip().splitlines() or ["no message"])[-1]
        raise ModelFmuError(f"{script}: packaging as FMI {fmi_version} failed: {why}")
    return Path(res.stdout.strip().splitlines()[-1])


_BUILD = """
import json, sys
from pathlib import Path
from {module} import FmuBuilder
job = json.loads(sys.argv[1])
print(FmuBuilder.build_FMU(Path(job["script"]), dest=job["dest"], project_files=[Path(p) for p in job["resources"]],
                           **job["flags"]))
"""
