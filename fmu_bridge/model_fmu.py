"""Packaging a Python model class as an FMU (pythonfmu for FMI 2.0, pythonfmu3 for FMI 3.0).

The model script defines one ``pythonfmu.Fmi2Slave`` (or ``pythonfmu3.Fmi3Slave``)
subclass; resources (an MJCF file, a checkpoint) travel in the FMU's ``resources/``.
The same model then runs as a hycosim node (``"fmu": "model.fmu"``) and in plain fmpy.

Two things to know about such FMUs: the importing process needs a Python runtime with
the model's packages (pythonfmu embeds the interpreter it was built with), and pythonfmu
writes no InitialUnknowns unless outputs are registered with ``initial=exact``.
"""

from __future__ import annotations

from pathlib import Path


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
    try:
        if fmi_version.startswith("3"):
            from pythonfmu3 import FmuBuilder

            path = FmuBuilder.build_FMU(script, dest=dest, project_files=resources or [],
                                        canGetAndSetFMUState=can_get_and_set_state,
                                        canSerializeFMUState=can_get_and_set_state)
        else:
            from pythonfmu import FmuBuilder

            path = FmuBuilder.build_FMU(script, dest=dest, project_files=resources or [],
                                        canGetAndSetFMUstate=can_get_and_set_state,
                                        canSerializeFMUstate=can_get_and_set_state)
    except Exception as exc:
        raise ModelFmuError(f"{script}: packaging as FMI {fmi_version} failed: {exc}") from None
    return Path(path)
