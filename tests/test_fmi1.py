"""FMI 1.0 co-simulation FMUs as nodes (fmpy's FMI 1.0 classes): FMI 1.0 builds of the
benchmarks' small models run as their FMI 2.0 builds do, in processes and in one process;
validate and fmu inspect say what FMI 1.0 cannot take part in. Model Exchange: test_model_exchange.py;
against ECOS, libcosim and fmpy.simulate_fmu: benchmarks/crosscheck.py."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.helpers import hycosim, read_rows, write_project


@pytest.fixture(scope="module")
def builds(tmp_path_factory) -> tuple[dict[str, Path], dict[str, Path]]:
    if shutil.which("gcc") is None:
        pytest.skip("needs gcc")
    from benchmarks._small_fmus import build, build1

    root = tmp_path_factory.mktemp("small")
    return build1(root / "fmi1"), build(root / "fmi2")


def _system(path: Path, fmus: dict[str, Path]) -> Path:
    """A bouncing ball (a state event inside its steps; a parameter set) whose height, bounce
    count and falling flag feed a feedthrough of each type, beside a Dahlquist → feedthrough chain."""
    return write_project(path, [
        {"nodeName": "ball", "UID": 1, "fmu": str(fmus["Ball"]), "parameters": {"e": 0.7},
         "output": ["h", "v", {"name": "bounces", "type": "Integer"}, {"name": "falling", "type": "Boolean"}]},
        {"nodeName": "types", "UID": 2, "fmu": str(fmus["Types"]), "parameters": {"gain": 2.0, "offset": 10},
         "input": ["ru", {"name": "iu", "type": "Integer"}, {"name": "bu", "type": "Boolean"}],
         "output": ["ry", {"name": "iy", "type": "Integer"}, {"name": "by", "type": "Boolean"}]},
        {"nodeName": "dahlquist", "UID": 3, "fmu": str(fmus["Dahlquist"]), "output": ["x"]},
        {"nodeName": "ft", "UID": 4, "fmu": str(fmus["Feedthrough"]), "input": ["u"], "output": ["y"]},
    ], [{"from": "ball.h", "to": "types.ru", "factor": 100.0}, {"from": "ball.bounces", "to": "types.iu"},
        {"from": "ball.falling", "to": "types.bu"}, {"from": "dahlquist.x", "to": "ft.u", "factor": 2.0, "offset": 1.0}],
        cosim={"stepSize": 0.01, "stopTime": 0.6}, name="fmi1")


def _run(cfg: Path, runs: Path, *flags: str) -> Path:
    res = hycosim("run", str(cfg), "--runs-dir", str(runs), "--no-progress", *flags)
    assert res.returncode == 0, res.stderr
    return next(runs.iterdir())


def test_fmi_1_co_simulation_fmus_record_what_their_fmi_2_builds_record(tmp_path, builds):
    fmi1, fmi2 = builds
    old = _system(tmp_path / "old.json", fmi1)
    apart, together = _run(old, tmp_path / "apart"), _run(old, tmp_path / "together", "--in-process")
    new = _run(_system(tmp_path / "new.json", fmi2), tmp_path / "new")
    assert (apart / "values.csv").read_bytes() == (together / "values.csv").read_bytes() \
        == (new / "values.csv").read_bytes()
    rows = read_rows(apart)
    assert int(rows[-1]["ball.bounces"]) == 1 and float(rows[0]["types.ry"]) == 200.0  # the bounce; gain 2 set


def test_validate_and_fmu_inspect_say_what_an_fmi_1_fmu_cannot_take_part_in(tmp_path, builds):
    fmi1, _ = builds
    cfg = _system(tmp_path / "old.json", fmi1)
    res = hycosim("validate", str(cfg))
    assert res.returncode == 0, res.stderr
    said = " ".join(res.stdout.split())
    assert said.count("its FMU is FMI 1.0, which has no state to get or set") >= 8  # checkpoints, iteration × 4
    assert "node 'ft': its FMU is FMI 1.0, which says nothing of which inputs" in " ".join(res.stderr.split())
    res = hycosim("fmu", "inspect", str(fmi1["Ball"]))
    assert res.returncode == 0, res.stderr
    said = " ".join(res.stdout.replace("│", " ").split())
    assert "Ball.fmu: FMI 1.0" in said and "initialised whole in its setup" in said
