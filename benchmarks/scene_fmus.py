"""Rod and robot-scene FMUs against bare MuJoCo stepping the same models, at a 10 ms macro step.

"Bare" is the model class in-process (RodModel.advance: mj_step ×10; RobotScene.step:
servos, kinematics, collision, reach IK). "FMU" is the pythonfmu FMU driven through
fmpy's FMU2Slave: set inputs, doStep, get outputs, per macro step. Target: FMU < 2× bare.

    python benchmarks/scene_fmus.py [--seconds 20] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import _table  # noqa: E402

from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from hycosim.scenario.robot import kr6  # noqa: E402
from hycosim.scenario.robot.scene import RobotScene  # noqa: E402
from hycosim.scenario.rod.model import RodModel  # noqa: E402
from hycosim.scenario.scene_fmus import build_scene_fmus  # noqa: E402

H = 0.01


def _slave(path: Path):
    md = read_model_description(str(path))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="bench")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    return fmu, {v.name: v.valueReference for v in md.modelVariables}


def rod(steps: int, fmu_path: Path) -> tuple[float, float]:
    """Seconds a 10 ms macro step takes the bare rod model and its FMU through fmpy."""
    model = RodModel()
    t0 = time.perf_counter()
    for _ in range(steps):
        model.advance(H)
        model.outputs()
    bare = steps / (time.perf_counter() - t0)
    fmu, vr = _slave(fmu_path)
    outs = [vr[n] for n in ("angle", "omega", "grasp_x", "grasp_y", "grasp_z", "tip_x", "tip_y", "tip_z")]
    ins = [vr[n] for n in ("grip_x", "grip_y", "grip_z", "meas_angle")]
    t0 = time.perf_counter()
    for k in range(steps):
        fmu.setReal(ins, [0.62, 0.0, 0.6, 0.0])
        fmu.doStep(k * H, H)
        fmu.getReal(outs)
    wrapped = steps / (time.perf_counter() - t0)
    fmu.terminate()
    fmu.freeInstance()
    return bare, wrapped


def robot(steps: int, fmu_path: Path) -> tuple[float, float]:
    """Seconds a 10 ms macro step takes the bare robot scene and its FMU through fmpy."""
    scene = RobotScene()
    targets = [kr6.HOME + np.radians([20 * math.sin(k / 50), 10 * math.sin(k / 70), 0, 0, 0, 0]) for k in range(steps)]
    t0 = time.perf_counter()
    for k in range(steps):
        scene.step(H, targets[k], False, 0.5 * math.sin(k * H * 4.8))
    bare = steps / (time.perf_counter() - t0)
    fmu, vr = _slave(fmu_path)
    ins = [vr[f"q_cmd{i}"] for i in range(1, 7)] + [vr["rod_angle"]]
    outs = [vr[n] for n in ("q1", "q2", "q3", "q4", "q5", "q6", "tcp_x", "tcp_y", "tcp_z", "dist", "gap")]
    bools = [vr[n] for n in ("grasped", "collision", "reachable", "near_miss")]
    t0 = time.perf_counter()
    for k in range(steps):
        fmu.setReal(ins, [*targets[k], 0.5 * math.sin(k * H * 4.8)])
        fmu.doStep(k * H, H)
        fmu.getReal(outs)
        fmu.getBoolean(bools)
    wrapped = steps / (time.perf_counter() - t0)
    fmu.terminate()
    fmu.freeInstance()
    return bare, wrapped


def main() -> None:
    """Build the FMUs, measure both models bare and as FMUs and print the ratios (``--json``: one object
    a model)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="simulated seconds per measurement")
    ap.add_argument("--json", action="store_true")
    _table.add_argument(ap)
    args = ap.parse_args()
    steps = int(args.seconds / H)
    with tempfile.TemporaryDirectory() as tmp:
        fmus = build_scene_fmus(Path(tmp))
        figures = {"rod": rod(steps, fmus["rod"]), "robot": robot(steps, fmus["robot"])}
    _table.write(args.table, _table.Table(
        f"Macro steps of 10 ms per second over {args.seconds:g} s simulated:", ["model", "bare MuJoCo", "FMU",
                                                                               "FMU cost (goal < 2×)"],
        [[name, _table.rate(bare), _table.rate(wrapped), f"{bare / wrapped:.2f}×"]
         for name, (bare, wrapped) in figures.items()]))
    for name, (bare, wrapped) in figures.items():
        if args.json:
            print(json.dumps({"model": name, "bare_steps_per_s": bare, "fmu_steps_per_s": wrapped,
                              "cost_ratio": bare / wrapped}))
        else:
            print(f"{name:<6} bare {bare:9.0f} macro steps/s   FMU {wrapped:9.0f} macro steps/s   "
                  f"FMU cost {bare / wrapped:.2f}× bare (target < 2×)")


if __name__ == "__main__":
    main()
