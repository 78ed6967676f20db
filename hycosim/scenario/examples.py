"""The grasp demo's example projects, registered as ``hycosim.examples`` entry points.

Import-light on purpose: ``hycosim examples`` loads this in a core install, where MuJoCo and
torch are missing; the scene FMUs' builder is imported only when an example is written.
"""

from __future__ import annotations

from pathlib import Path

from hycosim.core.examples import Example

CONFIGS = Path(__file__).resolve().parent / "configs"


def _build_scene_fmus(folder: Path) -> None:
    from hycosim.scenario.scene_fmus import ensure_scene_fmus

    ensure_scene_fmus(folder)


GRASP = Example("grasp", "the paper's grasp in simulation: MuJoCo rod, KR6 R700 scene, scripted controller "
                "(Python nodes)", CONFIGS / "grasp.json", extra="scenario")
GRASP_FMU = Example("grasp-fmu", "the same grasp with the rod and the robot scene as FMUs, built into the "
                    "folder", CONFIGS / "grasp-fmu.json", extra="scenario", build_fmus=_build_scene_fmus)
GRASP_POLICY = Example("grasp-policy", "the grasp driven by the pretrained DDPG policy", CONFIGS / "grasp-policy.json",
                       extra="scenario")
GRASP_PAPER = Example("grasp-paper", "the paper's setup: scene FMUs, the policy, the camera correcting the twin, "
                      "paced at real time", CONFIGS / "grasp-paper.json", extra="scenario",
                      build_fmus=_build_scene_fmus)
