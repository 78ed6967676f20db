"""The initialisation phase: consistent outputs at the start, in processes and in one process,
against ECOS, for FMUs and Python nodes; an initial algebraic loop solved or named."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hycosim.core.schema import Route
from hycosim.master import initialisation
from tests.helpers import hycosim, read_rows, run_project, write_project
from tests.wire_strategies import values


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> dict[str, Path]:
    from benchmarks._small_fmus import build

    return build(tmp_path_factory.mktemp("small"))


def _chain(path: Path, fmus: dict[str, Path], stop: float = 0.05, **cosim) -> Path:
    """Dahlquist.x --(2x + 1)--> ft (y = u) --> ft2 (y = u): a direct-feedthrough chain."""
    return write_project(path, [
        {"nodeName": "dahlquist", "UID": 1, "fmu": str(fmus["Dahlquist"]), "input": [], "output": ["x"]},
        {"nodeName": "ft", "UID": 2, "fmu": str(fmus["Feedthrough"]), "input": ["u"], "output": ["y"]},
        {"nodeName": "ft2", "UID": 3, "fmu": str(fmus["Feedthrough"]), "input": ["u"], "output": ["y"]},
    ], [{"from": "dahlquist.x", "to": "ft.u", "factor": 2.0, "offset": 1.0}, {"from": "ft.y", "to": "ft2.u"}],
        cosim={"stepSize": 0.01, "stopTime": stop, **cosim}, name="chain")


def _loop(path: Path, fmus: dict[str, Path], factor: float) -> Path:
    """ft.y --(factor·y + 1)--> ft2.u, ft2.y --(factor·y)--> ft.u: an algebraic loop at the start."""
    return write_project(path, [
        {"nodeName": "ft", "UID": 1, "fmu": str(fmus["Feedthrough"]), "input": ["u"], "output": ["y"]},
        {"nodeName": "ft2", "UID": 2, "fmu": str(fmus["Feedthrough"]), "input": ["u"], "output": ["y"]},
    ], [{"from": "ft.y", "to": "ft2.u", "factor": factor, "offset": 1.0},
        {"from": "ft2.y", "to": "ft.u", "factor": factor, "offset": 0.0}],
        cosim={"stepSize": 0.01, "stopTime": 0.03}, name="loop")


def _run(cfg: Path, runs: Path, *flags: str) -> Path:
    res = hycosim("run", str(cfg), "--runs-dir", str(runs), "--no-progress", *flags)
    assert res.returncode == 0, res.stderr
    return next(runs.iterdir())


def test_a_feedthrough_chain_starts_consistent_in_processes_and_in_one_process(tmp_path, small):
    cfg = _chain(tmp_path / "chain.json", small)
    apart, together = _run(cfg, tmp_path / "apart"), _run(cfg, tmp_path / "together", "--in-process")
    first = read_rows(apart)[0]
    # 2·x(0) + 1 = 3 reaches ft.u, ft.y, ft2.u and ft2.y at t = 0: no link starts a step late.
    assert [float(first[c]) for c in ("dahlquist.x", "ft.u", "ft.y", "ft2.u", "ft2.y")] == [1.0, 3.0, 3.0, 3.0, 3.0]
    assert (apart / "values.csv").read_bytes() == (together / "values.csv").read_bytes()
    meta = json.loads((apart / "meta.json").read_text())
    assert meta["initialisation"] == [{"nodes": ["ft"], "loop": False, "sweeps": 1},
                                      {"nodes": ["ft2"], "loop": False, "sweeps": 1},
                                      {"nodes": ["dahlquist", "ft", "ft2"], "left": "initialization mode"}]
    # Without the phase the nodes start from what their setup made (y = 0), a step late per link.
    off = _chain(tmp_path / "off.json", small, initialize={"enabled": False})
    row = read_rows(_run(off, tmp_path / "off"))[0]
    assert (float(row["ft.u"]), float(row["ft.y"]), float(row["ft2.y"])) == (3.0, 0.0, 0.0)


def _late(path: Path, fmus: dict[str, Path], **cosim) -> Path:
    """Constant.y (3) --(2x + 1)--> ft1 --> ft2, feedthroughs that compute y = u only when they
    leave initialisation mode and in their steps (as pythonfmu FMUs commonly do)."""
    return write_project(path, [
        {"nodeName": "source", "UID": 1, "fmu": str(fmus["Constant"]), "input": [], "output": ["y"]},
        {"nodeName": "ft1", "UID": 2, "fmu": str(fmus["LateFeedthrough"]), "input": ["u"], "output": ["y"]},
        {"nodeName": "ft2", "UID": 3, "fmu": str(fmus["LateFeedthrough"]), "input": ["u"], "output": ["y"]},
    ], [{"from": "source.y", "to": "ft1.u", "factor": 2.0, "offset": 1.0}, {"from": "ft1.y", "to": "ft2.u"}],
        cosim={"stepSize": 0.01, "stopTime": 0.03, **cosim}, name="late")


def test_fmus_that_compute_on_leaving_initialisation_mode_start_from_their_linked_inputs(tmp_path, small):
    # The start inputs are set inside initialisation mode, then every FMU leaves it: ft1 leaves
    # it on u = 7 (y = 7 at t = 0); ft2 on ft1's y as read inside the mode (0), and its first
    # step takes ft1's 7 (y = 7 from t = 0.01). ECOS gives the same (benchmarks/crosscheck.py).
    cfg = _late(tmp_path / "late.json", small)
    apart, together = _run(cfg, tmp_path / "apart"), _run(cfg, tmp_path / "together", "--in-process")
    rows = read_rows(apart)
    assert [(float(r["ft1.y"]), float(r["ft2.u"]), float(r["ft2.y"])) for r in rows[:3]] == [
        (7.0, 7.0, 0.0), (7.0, 7.0, 7.0), (7.0, 7.0, 7.0)]
    assert (apart / "values.csv").read_bytes() == (together / "values.csv").read_bytes()
    done = json.loads((apart / "meta.json").read_text())["initialisation"]
    assert done[-1] == {"nodes": ["source", "ft1", "ft2"], "left": "initialization mode"}
    # Without the phase every FMU leaves the mode at its first step, on its inputs' start values:
    # ft1 gives 0 at t = 0, as an importer that sets the inputs after leaving it would.
    off = read_rows(_run(_late(tmp_path / "off.json", small, initialize={"enabled": False}), tmp_path / "off"))
    assert [float(r["ft1.y"]) for r in off[:2]] == [0.0, 7.0]


def test_the_chain_agrees_with_ecos_at_every_point_where_the_schemes_agree(tmp_path, small):
    """ECOS (an in-process FMI master) from the same package: the start, every state and every
    input to the bit. A direct-feedthrough output differs by design: ECOS reads it after it has
    set the point's inputs (y(t) = u(t)); hycosim records what the FMU gave at the end of its
    step (y(t) = u(t − H), the input it stepped on): one step apart, exactly."""
    ecospy = pytest.importorskip("ecospy", reason="ecospy is in the [test] extra")
    from hycosim.core.config import load_project
    from hycosim.fmi.ssp import write_ssp

    cfg = _chain(tmp_path / "chain.json", small, stop=0.2)
    rows = read_rows(run_project(cfg, tmp_path / "runs"))
    sim = ecospy.EcosSimulation(ssp_path=str(write_ssp(load_project(cfg), tmp_path / "chain.ssp")), step_size=0.01)
    sim.init()
    names = ("dahlquist.x", "ft.u", "ft2.u", "ft.y", "ft2.y")
    ecos = []
    for k in range(len(rows)):
        if k:
            sim.step(1)
        ecos.append({n: sim.get_real(n.replace(".", "::")) for n in names})
    assert {n: float(rows[0][n]) for n in names} == ecos[0]
    for k, row in enumerate(rows):
        assert {n: float(row[n]) for n in names[:3]} == {n: ecos[k][n] for n in names[:3]}, k
        if k:
            assert float(row["ft.y"]) == ecos[k - 1]["ft.y"] and float(row["ft2.y"]) == ecos[k - 1]["ft2.y"], k


def test_an_initial_algebraic_loop_settles_at_its_fixed_point_or_is_named(tmp_path, small):
    # a = 0.5·b, b = 0.5·a + 1: a = 2/3, b = 4/3.
    run_dir = _run(_loop(tmp_path / "half.json", small, 0.5), tmp_path / "half")
    first = read_rows(run_dir)[0]
    assert abs(float(first["ft.y"]) - 2 / 3) < 1e-9 and abs(float(first["ft2.y"]) - 4 / 3) < 1e-9
    done = json.loads((run_dir / "meta.json").read_text())["initialisation"]
    assert done[0]["nodes"] == ["ft", "ft2"] and done[0]["loop"] and 10 < done[0]["sweeps"] < 100
    # a = b, b = a + 1: no fixed point. The run fails naming the loop and its changes, exit 3,
    # and its directory says so.
    res = hycosim("run", str(_loop(tmp_path / "one.json", small, 1.0)), "--runs-dir", str(tmp_path / "one"),
                  "--no-progress")
    assert res.returncode == 3, res.stderr
    assert "algebraic loop ft.u → ft.y → ft2.u → ft2.y → ft.u did not settle in 100 sweeps" in res.stderr
    assert "ft.y" in res.stderr.split("last changes:")[1] and "Traceback" not in res.stderr
    meta = json.loads((next((tmp_path / "one").iterdir()) / "meta.json").read_text())
    assert meta["status"] == "failed" and "did not settle" in meta["reason"]


def test_a_python_node_with_a_start_feedthrough_takes_part_and_one_without_does_not(tmp_path):
    cfg = write_project(tmp_path / "py.json", [
        {"nodeName": "ramp", "UID": 1, "model": "ramp", "parameters": {"a": 2.0, "b": 0.5}, "output": ["y", "v"]},
        {"nodeName": "s", "UID": 2, "model": "tests.nodes:Static", "parameters": {"k": 3.0}, "input": ["u"],
         "output": ["y"]},
        {"nodeName": "g", "UID": 3, "model": "gain", "parameters": {"k": 3.0}, "input": ["u"], "output": ["y"]},
    ], [{"from": "ramp.y", "to": "s.u"}, {"from": "ramp.y", "to": "g.u"}], cosim={"stepSize": 0.1, "stopTime": 0.3})
    apart, together = _run(cfg, tmp_path / "apart"), _run(cfg, tmp_path / "together", "--in-process")
    first = read_rows(apart)[0]
    assert float(first["s.u"]) == 2.0 and float(first["s.y"]) == 6.0  # 3·u at the start
    assert float(first["g.y"]) == 0.0  # the gain declares no start feedthrough: what its setup made
    assert (apart / "values.csv").read_bytes() == (together / "values.csv").read_bytes()
    assert json.loads((apart / "meta.json").read_text())["initialisation"] == [
        {"nodes": ["s"], "loop": False, "sweeps": 1}]


def _route(src: str, dst: str, sp: str = "y", dp: str = "u") -> Route:
    return Route(0, src, sp, dst, dp, None, "hold")


nodes = st.lists(st.sampled_from("abcdef"), min_size=1, max_size=6, unique=True)


@given(order=nodes, pairs=st.lists(st.tuples(st.sampled_from("abcdef"), st.sampled_from("abcdef")), max_size=12),
       reading=st.sets(st.sampled_from("abcdef")))
def test_the_plan_puts_each_node_after_those_it_reads_and_loops_together(order, pairs, reading):
    routes = [_route(s, d) for s, d in pairs if s in order and d in order]
    feedthrough = {n: {"y": {"u"}} if n in reading else {} for n in order}
    groups = initialisation.plan(routes, "free", feedthrough, order)
    placed = {n: i for i, g in enumerate(groups) for n in g.nodes}
    taking = {r.dst_node for r in routes if r.dst_node in reading}
    assert set(placed) == taking  # exactly the nodes that read a linked input at the start
    for r in routes:
        if r.src_node in taking and r.dst_node in taking:
            assert placed[r.src_node] <= placed[r.dst_node]
            if placed[r.src_node] == placed[r.dst_node]:
                assert groups[placed[r.src_node]].loop
    for g in groups:
        if len(g.nodes) == 1 and not g.loop:
            assert not any(r.src_node == r.dst_node == g.nodes[0] for r in routes)


@given(said=values | st.dictionaries(st.sampled_from(["y", "z", "q"]) | st.text(max_size=3),
                                     st.lists(st.sampled_from(["u", "w"]) | values, max_size=3) | values,
                                     max_size=4))
def test_a_hellos_start_feedthrough_is_taken_only_within_the_nodes_ports(said):
    checked = initialisation.checked_feedthrough(said, ["u"], ["y", "z"])
    assert set(checked) <= {"y", "z"} and all(reads and reads <= {"u"} for reads in checked.values())


def test_validate_names_an_fmu_output_whose_start_dependencies_are_unsaid_and_the_run_reads_them_all(tmp_path):
    """A model structure without ``dependencies`` (pythonfmu's unless told): validate warns, and
    the initialisation takes the output as reading every input, which for y = u is right."""
    from benchmarks._fmu_build import native_fmu
    from benchmarks._small_fmus import MODELS, SOURCE, model_description

    md = model_description("Feedthrough").replace(' dependencies="1"', "")
    md = md[:md.index("    <InitialUnknowns>")] + md[md.index("</InitialUnknowns>\n") + len("</InitialUnknowns>\n"):]
    assert "dependencies" not in md and "InitialUnknowns" not in md
    fmus = {"Feedthrough": native_fmu(SOURCE, "Feedthrough", md, tmp_path / "Feedthrough.fmu",
                                      [f"-DMODEL={MODELS['Feedthrough'][0]}"]),
            "Dahlquist": native_fmu(SOURCE, "Dahlquist", model_description("Dahlquist"), tmp_path / "Dahlquist.fmu",
                                    [f"-DMODEL={MODELS['Dahlquist'][0]}"])}
    cfg = _chain(tmp_path / "chain.json", fmus)
    res = hycosim("validate", str(cfg))
    assert res.returncode == 0, res.stderr
    for node in ("ft", "ft2"):
        assert (f"node {node!r}: its FMU's model structure does not say which inputs y depends on at the start"
                in res.stderr)
    assert "node 'dahlquist'" not in res.stderr  # no input: nothing unsaid
    first = read_rows(run_project(cfg, tmp_path / "runs"))[0]
    assert (float(first["ft.y"]), float(first["ft2.y"])) == (3.0, 3.0)


def test_fmi3_fmus_take_part_in_the_initialisation_as_fmi2_ones_do(tmp_path, small):
    """An FMI 3 feedthrough (pythonfmu3, y = 2u read at once) behind the Dahlquist and before a
    second one: the first row is consistent through both; without the phase it starts late."""
    from hycosim.bridge.model_fmu import build_model_fmu
    from tests.helpers import REPO

    ft3 = build_model_fmu(REPO / "tests" / "models" / "feedthrough_model3.py", tmp_path, fmi_version="3.0")
    nodes = [{"nodeName": "dahlquist", "UID": 1, "fmu": str(small["Dahlquist"]), "input": [], "output": ["x"]},
             {"nodeName": "a", "UID": 2, "fmu": str(ft3), "input": ["u"], "output": ["y"]},
             {"nodeName": "b", "UID": 3, "fmu": str(ft3), "input": ["u"], "output": ["y"]}]
    links = [{"from": "dahlquist.x", "to": "a.u", "factor": 2.0, "offset": 1.0}, {"from": "a.y", "to": "b.u"}]
    firsts = {}
    for enabled in (True, False):
        cfg = write_project(tmp_path / f"p-{enabled}.json", nodes, links, name="fmi3",
                            cosim={"stepSize": 0.01, "stopTime": 0.03, "initialize": {"enabled": enabled}})
        firsts[enabled] = {k: float(v) for k, v in read_rows(_run(cfg, tmp_path / f"runs-{enabled}"))[0].items()
                           if k not in ("step", "mode")}
    assert (firsts[True]["a.u"], firsts[True]["a.y"], firsts[True]["b.u"], firsts[True]["b.y"]) == (3.0, 6.0, 6.0, 12.0)
    assert (firsts[False]["a.y"], firsts[False]["b.y"]) == (0.0, 0.0)
