"""Co-simulations over real Zenoh on 127.0.0.1, every node its own process, checked in closed form."""

from __future__ import annotations

import math
from pathlib import Path

from tests.helpers import column, meta, read_rows, run_project, write_project

H = 0.01


def test_two_nodes_show_the_one_step_jacobi_delay_exactly(tmp_path):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}], cosim={"stepSize": H, "stopTime": 1.0})
    run = run_project(cfg, tmp_path / "runs")
    rows = read_rows(run)
    assert len(rows) == 101
    clock, g, gu = column(rows, "clock.y"), column(rows, "g.y"), column(rows, "g.u")
    for k, row in enumerate(rows):
        assert int(row["step"]) == k
        assert math.isclose(float(row["t"]), k * H, abs_tol=1e-12)
        assert math.isclose(clock[k], k * H, abs_tol=1e-12)
        assert gu[k] == clock[k]  # routed at T_k ...
    assert g[0] == 0.0
    for k in range(1, len(rows)):
        assert g[k] == clock[k - 1]  # ... and seen in the output one macro step later
    assert meta(run)["status"] == "completed"


def test_four_node_chain_delays_one_step_per_hop(tmp_path):
    nodes = [{"nodeName": "clock", "UID": 1, "model": "ramp", "parameters": {"a": 1.0, "b": 2.0}, "output": ["y", "v"]}]
    links = []
    prev = "clock"
    for i in range(1, 4):
        nodes.append({"nodeName": f"g{i}", "UID": 1 + i, "model": "gain", "parameters": {"k": 1.0, "b": 0.0},
                      "input": ["u"], "output": ["y"]})
        links.append({"from": f"{prev}.y", "to": f"g{i}.u"})
        prev = f"g{i}"
    cfg = write_project(tmp_path / "p.json", nodes, links, cosim={"stepSize": H, "stopTime": 0.5})
    rows = read_rows(run_project(cfg, tmp_path / "runs"))
    clock = column(rows, "clock.y")
    for i in range(1, 4):
        gi = column(rows, f"g{i}.y")
        assert gi[:i] == [0.0] * i
        assert gi[i:] == clock[:len(rows) - i]


def test_gain_ring_matches_closed_form(tmp_path):
    n = 4
    nodes = [{"nodeName": f"n{i}", "UID": i, "model": "gain", "parameters": {"k": 0.5, "b": 1.0},
              "input": ["u"], "output": ["y"]} for i in range(n)]
    links = [{"from": f"n{i}.y", "to": f"n{(i + 1) % n}.u"} for i in range(n)]
    cfg = write_project(tmp_path / "p.json", nodes, links, cosim={"stepSize": 0.1, "stopTime": 3.0})
    rows = read_rows(run_project(cfg, tmp_path / "runs"))
    for k, row in enumerate(rows):
        for i in range(n):
            # y_0 = 0.5·0 + 1, y_k = 0.5·y_{k-1} + 1  ⇒  y_k = 2 − 0.5^k
            assert math.isclose(float(row[f"n{i}.y"]), 2 - 0.5 ** k, rel_tol=0, abs_tol=1e-12)


def test_a_plain_run_records_in_its_flat_loop_what_the_general_loop_records(tmp_path):
    """A run with nothing at its points but routing and releases takes them in the relay's flat
    loop (master/plain_loop.py); the same run paced in real time (far faster than the clock)
    goes through the general loop, and the two record the same values, byte for byte, and
    the same timing rows, each node's arrival in each."""
    nodes = [{"nodeName": "clock", "UID": 1, "model": "ramp", "parameters": {"a": 0.3, "b": 0.1},
              "output": ["y", "v"]}]
    nodes += [{"nodeName": f"g{i}", "UID": 2 + i, "model": "gain", "parameters": {"k": 0.7, "b": 0.2},
               "input": ["u"], "output": ["y"]} for i in range(3)]
    links = [{"from": "clock.y", "to": "g0.u"}, {"from": "g0.y", "to": "g1.u", "factor": 3.0, "offset": -1.0},
             {"from": "g1.y", "to": "g2.u"}]
    runs = {}
    for how, cosim in (("plain", {}), ("general", {"realTime": 0.001})):
        cfg = write_project(tmp_path / f"{how}.json", nodes, links,
                            cosim={"stepSize": H, "stopTime": 0.7, **cosim}, name="same")
        runs[how] = run_project(cfg, tmp_path / how)
    assert meta(runs["plain"])["points"].startswith("plain")
    assert meta(runs["general"])["points"] == "each point through the algorithm (real time)"
    values = {how: (run / "values.csv").read_bytes() for how, run in runs.items()}
    assert values["plain"] == values["general"] and values["plain"].count(b"\n") == 72
    timing = {how: read_rows(run, "timing.csv") for how, run in runs.items()}
    assert list(timing["plain"][0]) == list(timing["general"][0])
    assert [(r["step"], r["t"]) for r in timing["plain"]] == [(r["step"], r["t"]) for r in timing["general"]]
    for row in timing["plain"][1:]:
        assert row["lateness_s"] == "" and row["holder"] in ("clock", "g0", "g1", "g2")
        assert all(float(row[f"arrival_s:{n}"]) > 0 for n in ("clock", "g0", "g1", "g2"))
    assert all(row["lateness_s"] != "" for row in timing["general"])


def test_modules_in_the_working_folder_do_not_replace_the_libraries_of_the_nodes(tmp_path):
    """``hycosim run`` in a folder holding a zenoh.py or grp.py (a stdlib module that torch and
    shutil import): the nodes it starts import the installed libraries, not the user's files."""
    import subprocess
    import sys

    from tests.helpers import env

    for name in ("zenoh", "grp", "msgpack"):
        (tmp_path / f"{name}.py").write_text(f"raise SystemExit('the working folder\\'s {name}.py was imported')\n")
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}], cosim={"stepSize": 0.1, "stopTime": 1.0})
    console_script = Path(sys.executable).parent / "hycosim"
    res = subprocess.run([str(console_script), "run", cfg.name, "--runs-dir", "runs", "--no-progress"],
                         capture_output=True, text=True, timeout=120, env=env(), cwd=tmp_path)
    assert res.returncode == 0, res.stdout + res.stderr
    run = next((tmp_path / "runs").iterdir())
    assert not any("was imported" in p.read_text() for p in run.glob("*.stderr.txt"))
    rows = read_rows(run)
    assert len(rows) == 11 and column(rows, "g.u") == column(rows, "clock.y")


def _grasp_parameters() -> dict:
    import json

    from tests.helpers import REPO

    return json.loads((REPO / "hycosim" / "scenario" / "configs" / "grasp-policy.json").read_text())["nodeLists"][0]["parameters"]


def test_every_shipped_model_gives_exactly_the_outputs_it_declares(tmp_path):
    """The port names a model declares are what load and validate check entries against: they
    must be the model's real outputs, not a list that drifted from its code."""
    from hycosim.node.loader import REFERENCE_MODELS, model_class
    from hycosim.node.interface import AsyncSource, NodeContext
    from hycosim.core.schema import Node as NodeSpec

    grasp = _grasp_parameters()
    for name in REFERENCE_MODELS:
        asynchronous = name in ("camera", "ramp_source")
        cls = model_class(NodeSpec.model_validate({"nodeName": "n", "UID": 1, "model": name, "async": asynchronous}))
        assert cls.OUTPUTS, name
        params = {k: v for k, v in grasp.items() if cls.PARAMETERS is not None and k in cls.PARAMETERS}
        impl = cls()
        impl.setup(NodeContext("n", 1, [], [], params, 0.01, 0.0, tmp_path))
        try:
            if isinstance(impl, AsyncSource):
                samples = list(impl.samples_until(0.2))
                assert samples and all(set(values) == cls.OUTPUTS for _, values in samples), name
            else:
                assert set(impl.outputs()) == cls.OUTPUTS, name
                assert cls.INPUTS is not None, name
        finally:
            impl.teardown()
