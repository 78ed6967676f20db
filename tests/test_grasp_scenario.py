"""The grasp scenario end to end over real Zenoh: rod, robot scene and reference controller as processes."""

from __future__ import annotations

import json
import math
import threading
import zipfile
from pathlib import Path

from fmpy import simulate_fmu
from fmpy.validation import validate_fmu

from hycosim.scenario.rod.model import LIMITS, RodModel, RodParams
from hycosim.scenario.scene_fmus import build_scene_fmus
from tests.helpers import REPO, column, hycosim, read_rows, run_project


def _check_grasp(run: Path, rows: list[dict]) -> None:
    events = [json.loads(line) for line in (run / "events.jsonl").read_text().splitlines()]
    assert events and events[0]["to"] == "grasp"
    k = events[0]["step"]
    dist = column(rows, "robot.dist")
    assert dist[k] < 0.005  # grasped within 5 mm of the rod's grasp point
    assert not any(float(r["robot.collision"]) for r in rows)
    angle = column(rows, "rod.angle")
    held = angle[k + 20:]
    assert max(held) - min(held) < math.radians(2)  # the held rod follows the still gripper
    assert [r["mode"] for r in rows[k:]] == ["grasp"] * (len(rows) - k)
    # before the grasp the rod swung freely, exactly as the rod model alone does
    p = RodParams(length=0.6, mass=0.3, damping=0.002, pivot=(0.62, 0.0, 1.0), grasp_distance=0.4,
                  initial_angle=math.radians(40))
    alone = RodModel(p)
    for i in range(1, k):
        alone.advance(0.01)
        assert math.isclose(alone.angle, angle[i], abs_tol=1e-9)


def _shortened(src: Path, dst: Path, stop: float, replace: dict | None = None) -> Path:
    doc = json.loads(src.read_text())
    doc["coSimulation"]["stopTime"] = stop
    for node in doc["nodeLists"]:
        if "fmu" in node and replace:
            node["fmu"] = str(replace[node["nodeName"]])
    dst.write_text(json.dumps(doc))
    return dst


def test_reference_controller_grasps_the_rod_over_zenoh(tmp_path):
    cfg = _shortened(REPO / "hycosim" / "scenario" / "configs" / "grasp.json", tmp_path / "grasp.json", 2.0)
    run = run_project(cfg, tmp_path / "runs")
    _check_grasp(run, read_rows(run))


def test_scene_fmus_run_in_plain_fmpy_and_as_nodes(tmp_path):
    fmus = build_scene_fmus(tmp_path / "fmus")
    assert all(validate_fmu(str(p)) == [] for p in fmus.values())
    res = simulate_fmu(str(fmus["rod"]), stop_time=1.0, output_interval=0.01, output=["angle"],
                       start_values={"initial_angle": math.radians(30), "damping": 0.0})
    alone = RodModel(RodParams(initial_angle=math.radians(30), damping=0.0))
    alone.advance(1.0)
    assert math.isclose(res["angle"][-1], alone.angle, abs_tol=1e-9)
    res = simulate_fmu(str(fmus["robot"]), stop_time=0.2, output_interval=0.01, output=["q1", "reachable"],
                       start_values={"q_cmd1": 0.5})
    assert math.isclose(res["q1"][-1], 0.5) and math.isclose(res["q1"][1], math.radians(360) * 0.01)
    cfg = _shortened(REPO / "hycosim" / "scenario" / "configs" / "grasp-fmu.json", tmp_path / "grasp-fmu.json", 1.5,
                     {"rod": fmus["rod"], "robot": fmus["robot"]})
    res = hycosim("validate", str(cfg))
    assert res.returncode == 0, res.stderr
    doc = json.loads(cfg.read_text())
    doc["nodeLists"][0]["parameters"]["lenght"] = 0.6
    doc["nodeLists"][1]["output"][0] = {"name": "q1", "variable": "q_1"}
    (tmp_path / "misspelt.json").write_text(json.dumps(doc))
    res = hycosim("validate", str(tmp_path / "misspelt.json"))
    assert res.returncode == 2
    assert "nodeLists[0]: node 'rod': parameter 'lenght' is not a variable of Rod.fmu; did you mean 'length'?" in res.stderr
    assert "nodeLists[1]: node 'robot': RobotScene6.fmu has no variable for output 'q1' (variable 'q_1')" in res.stderr
    # A value outside the range the FMU declares is refused as the rod node refuses it, whatever the importer
    doc = json.loads(cfg.read_text())
    doc["nodeLists"][0]["parameters"]["length"] = -0.6
    doc["nodeLists"][1]["parameters"]["pivot_z"] = 1e6
    doc["nodeLists"][2]["parameters"]["mass"] = 0.0
    (tmp_path / "outside.json").write_text(json.dumps(doc))
    res = hycosim("validate", str(tmp_path / "outside.json"))
    assert res.returncode == 2
    text = res.stderr.replace("\n", " ")
    assert "node 'rod': parameter 'length' is -0.6, below the minimum 0.001 that Rod.fmu declares for it" in text
    assert "node 'robot': parameter 'pivot_z' is 1000000.0, above the maximum 100 that RobotScene6.fmu declares" in text
    assert "node 'controller': model 'hycosim.scenario.robot.controller:ReferenceController': parameter 'mass' is 0.0; " \
           "it must be at least 0.001" in text
    from hycosim.fmi.loader import describe

    bounds = {v.name: (float(v.min), float(v.max)) for v in describe(fmus["rod"]).modelVariables
              if v.causality == "parameter"}
    assert bounds["length"] == LIMITS["length"] and bounds["pivot_x"] == LIMITS["coordinate"]
    run = run_project(cfg, tmp_path / "runs")
    _check_grasp(run, read_rows(run))


def test_scene_fmus_rebuilt_while_read_and_twice_at_once_are_always_whole(tmp_path):
    """Rebuilding the FMUs a run may be opening (two trials commands, two test workers on a fresh
    clone): a reader meanwhile sees whole FMUs only, and two builds at once leave nothing beside them."""
    out = tmp_path / "build" / "fmus"
    build_scene_fmus(out)
    broken, reads, errors, stop = [], [0], [], threading.Event()

    def read() -> None:
        while not stop.is_set():
            for fmu in ("Rod.fmu", "RobotScene6.fmu"):
                try:
                    with zipfile.ZipFile(out / fmu) as z:
                        if z.testzip() is not None:
                            broken.append(f"{fmu}: bad CRC")
                except (OSError, zipfile.BadZipFile) as exc:
                    broken.append(f"{fmu}: {exc}")
                reads[0] += 1

    def build() -> None:
        try:
            build_scene_fmus(out)
        except Exception as exc:  # noqa: BLE001 - the assertion below names it
            errors.append(exc)

    reader = threading.Thread(target=read)
    builders = [threading.Thread(target=build) for _ in range(2)]
    reader.start()
    for b in builders:
        b.start()
    for b in builders:
        b.join(120)
    stop.set()
    reader.join(10)
    assert not errors and reads[0] > 0 and broken == [], broken[:3]
    assert sorted(p.name for p in out.iterdir()) == ["RobotScene6.fmu", "Rod.fmu"]
    assert all(validate_fmu(str(out / fmu)) == [] for fmu in ("Rod.fmu", "RobotScene6.fmu"))


def test_the_papers_scenario_config_validates_runs_and_names_a_missing_or_old_fmu(tmp_path):
    """hycosim/scenario/configs/grasp-paper.json: the rod and robot scene as FMUs, the camera and the policy."""
    fmus = build_scene_fmus(tmp_path / "build" / "fmus")
    (tmp_path / "configs").mkdir()
    cfg = _shortened(REPO / "hycosim" / "scenario" / "configs" / "grasp-paper.json", tmp_path / "configs" / "grasp-paper.json", 1.5)
    res = hycosim("validate", str(cfg))  # the shipped relative paths, ../build/fmus, resolve beside it
    assert res.returncode == 0, res.stderr
    run = run_project(cfg, tmp_path / "runs", timeout=180)
    rows = read_rows(run)
    events = [json.loads(line) for line in (run / "events.jsonl").read_text().splitlines()]
    assert events and events[0]["to"] == "grasp"  # the policy grasped the rod
    assert column(rows, "robot.dist")[events[0]["step"]] < 0.005
    assert any(r["rod.meas_valid"] == "1" for r in rows)  # through the FMU's input, the camera corrects the twin
    # An FMU built for other ports (an old build): every variable it lacks, named by validate.
    doc = json.loads(cfg.read_text())
    doc["nodeLists"][0]["input"] += ["meas_x", "meas_y"]
    (tmp_path / "configs" / "old.json").write_text(json.dumps(doc))
    res = hycosim("validate", str(tmp_path / "configs" / "old.json"))
    assert res.returncode == 2
    assert "node 'rod': Rod.fmu has no variable for input 'meas_x', input 'meas_y'" in res.stderr
    # A missing FMU: the file, and the command that builds it.
    fmus["robot"].unlink()
    res = hycosim("validate", str(cfg))
    assert res.returncode == 2 and f"FMU file {fmus['robot']} does not exist" in res.stderr
    assert f"build it with: hycosim scene fmus -o {fmus['robot'].parent}" in res.stderr
