"""Building the rod and robot-scene FMUs (``hycosim scene fmus``).

The FMUs carry the model code they need (``clients.rod.model``, ``clients.robot``) in
their resources, so they run in any FMI importer whose Python has mujoco and numpy.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

from fmu_bridge.model_fmu import build_model_fmu

HERE = Path(__file__).resolve().parent
_PACKAGED = ("__init__.py", "rod/__init__.py", "rod/model.py", "robot/__init__.py", "robot/kr6.py",
             "robot/ik.py", "robot/scene.py")


def build_scene_fmus(out_dir: Path) -> dict[str, Path]:
    """Write ``Rod.fmu`` and ``RobotScene6.fmu`` into ``out_dir``; return their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        staged = Path(tmp) / "clients"
        for rel in _PACKAGED:
            (staged / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(HERE / rel, staged / rel)
        return {
            "rod": build_model_fmu(HERE / "rod" / "rod_fmu.py", out_dir, resources=[staged]),
            "robot": build_model_fmu(HERE / "robot" / "robot_fmu.py", out_dir, resources=[staged]),
        }
