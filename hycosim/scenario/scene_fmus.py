"""Building the rod and robot-scene FMUs (``hycosim scene fmus``).

The FMUs carry the model code they need (``hycosim.scenario.rod.model``, ``hycosim.scenario.robot``)
in their resources, so they run in any FMI importer whose Python has mujoco and numpy.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from hycosim.core.folders import make_folder
from hycosim.bridge import model_fmu
from hycosim.bridge.model_fmu import build_model_fmu

HERE = Path(__file__).resolve().parent
# What builds them, named by the node loader when a project's FMU file is missing.
BUILD_COMMAND = "hycosim scene fmus -o {folder}"
_PACKAGED = ("__init__.py", "rod/__init__.py", "rod/model.py", "rod/bounded.py", "robot/__init__.py",
             "robot/kr6.py", "robot/ik.py", "robot/scene.py")


def build_scene_fmus(out_dir: Path) -> dict[str, Path]:
    """Write ``Rod.fmu`` and ``RobotScene6.fmu`` into ``out_dir``; return their paths."""
    make_folder(out_dir)
    # Built beside the destination and renamed into it: two builds at once (two trials
    # commands, two test processes on a fresh clone) each leave a whole FMU, and one that
    # reads the FMU meanwhile never opens half a zip.
    with tempfile.TemporaryDirectory() as tmp, tempfile.TemporaryDirectory(dir=out_dir, prefix=".build-") as fresh:
        # The model code keeps its import names (hycosim.scenario...) inside the FMU; the package's
        # own __init__ is left out (an empty one stands in), so the FMU needs nothing else of it.
        package = Path(tmp) / "hycosim"
        staged = package / "scenario"
        for rel in _PACKAGED:
            (staged / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(HERE / rel, staged / rel)
        (package / "__init__.py").write_text("")
        built = {
            "rod": build_model_fmu(HERE / "rod" / "rod_fmu.py", Path(fresh), resources=[package]),
            "robot": build_model_fmu(HERE / "robot" / "robot_fmu.py", Path(fresh), resources=[package]),
        }
        placed = {}
        for name, fmu in built.items():
            placed[name] = out_dir / fmu.name
            os.replace(fmu, placed[name])
        return placed


def _sources() -> list[Path]:
    # model_fmu: how they are packaged (which FMI capabilities they declare) counts as their source too.
    return [HERE / rel for rel in _PACKAGED] + [HERE / "rod" / "rod_fmu.py", HERE / "robot" / "robot_fmu.py",
                                                Path(model_fmu.__file__)]


def ensure_scene_fmus(out_dir: Path) -> dict[str, Path]:
    """The scene FMUs in ``out_dir``, built (again) when missing or older than their sources."""
    built = {"rod": out_dir / "Rod.fmu", "robot": out_dir / "RobotScene6.fmu"}
    newest = max(p.stat().st_mtime for p in _sources())
    if all(p.is_file() and p.stat().st_mtime >= newest for p in built.values()):
        return built
    return build_scene_fmus(out_dir)
