"""Master algorithms: multi-rate nodes and Gauss-Seidel coupling, end to end over Zenoh."""

from __future__ import annotations

import json
from pathlib import Path

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hycosim.core.config import ConfigError, parse_project
from tests.helpers import column, hycosim, meta, read_rows, run_killing, run_project, write_project


def _rates(tmp_path: Path, **cosim) -> Path:
    """A ramp at the base rate feeding a gain every 10 base steps, which feeds one every 50."""
    return write_project(tmp_path / "mr.json", [
        {"nodeName": "fast", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "mid", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"], "stepSize": 0.1},
        {"nodeName": "slow", "UID": 3, "model": "gain", "input": ["u"], "output": ["y"], "stepSize": 0.5},
    ], [{"from": "fast.y", "to": "mid.u"}, {"from": "mid.y", "to": "slow.u"}],
        cosim={"stepSize": 0.01, "stopTime": 1.05, **cosim})


def test_a_multi_rate_node_steps_at_its_multiples_holds_its_outputs_and_reads_inputs_at_its_step_start(tmp_path):
    run = run_project(_rates(tmp_path), tmp_path / "runs")
    rows = read_rows(run)
    assert len(rows) == 106
    stepped = [r["stepped"].split() for r in rows]
    assert stepped[0] == ["fast", "mid", "slow"] and stepped[10] == ["fast", "mid"] and stepped[11] == ["fast"]
    assert stepped[50] == ["fast", "mid", "slow"] and stepped[-1] == []  # nothing steps from stopTime
    mid, slow = column(rows, "mid.y"), column(rows, "slow.y")
    u_mid, u_slow = column(rows, "mid.u"), column(rows, "slow.u")
    for k in range(10, 105):
        # Held from the last step that ended by point k, which read its input where it began.
        assert mid[k] == pytest.approx(u_mid[10 * (k // 10) - 10]), k
    assert slow[:100] == [0.0] * 100 and slow[100:105] == [pytest.approx(u_slow[50])] * 5
    # The last steps, cut at stopTime, end there.
    assert mid[105] == pytest.approx(u_mid[100]) and slow[105] == pytest.approx(u_slow[100])
    assert u_slow[50] == pytest.approx(mid[50]) != 0.0
    m = meta(run)
    assert m["coupling"] == ("Jacobi; multi-rate: mid every 10 base steps, slow every 50 base steps; "
                             "releases batched over 10 base steps")
    report = json.loads(hycosim("report", str(run), "--json").stdout)
    assert report["node_steps"] == {"fast": 105, "mid": 11, "slow": 3}
    assert hycosim("report", str(run)).stdout.count("multi-rate: mid every 10 base steps") == 1


def test_batched_releases_record_what_one_release_per_base_point_records_with_fewer_messages(tmp_path):
    """A ramp at the base rate feeding a node every 5 base steps, which feeds one every 20, which
    feeds another at the base rate; stopTime off the grid: releases span 5 base steps (the
    ramp→mid link's period), and every recorded value, input and step mark is what a release
    at every base point gives."""
    runs = {}
    for batch in (True, False):
        cfg = write_project(tmp_path / f"b-{batch}.json", [
            {"nodeName": "fast", "UID": 1, "model": "ramp", "output": ["y", "v"]},
            {"nodeName": "mid", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"], "stepSize": 0.05},
            {"nodeName": "slow", "UID": 3, "model": "gain", "input": ["u"], "output": ["y"], "stepSize": 0.2},
            {"nodeName": "echo", "UID": 4, "model": "gain", "input": ["u"], "output": ["y"], "parameters": {"b": 0.5}},
        ], [{"from": "fast.y", "to": "mid.u"}, {"from": "mid.y", "to": "slow.u"}, {"from": "slow.y", "to": "echo.u"}],
            cosim={"stepSize": 0.01, "stopTime": 0.637, "batchReleases": batch})
        runs[batch] = run_project(cfg, tmp_path / f"runs-{batch}")
    batched, single = runs[True], runs[False]
    assert (batched / "values.csv").read_bytes() == (single / "values.csv").read_bytes()
    rows = read_rows(batched)
    assert len(rows) == 65 and len(set(column(rows, "fast.y"))) == 65 and len(set(column(rows, "echo.y"))) > 2
    assert meta(batched)["coupling"].endswith("releases batched over 5 base steps")
    assert meta(single)["coupling"].endswith("one release per base point (coSimulation.batchReleases is false)")
    # 64 base steps: 13 releases, the last 4 steps long, against 64.
    assert meta(batched)["messages"]["releases"] == 13 and meta(single)["messages"]["releases"] == 64
    assert meta(batched)["messages"]["received"] < meta(single)["messages"]["received"] / 2
    assert meta(batched)["dropped_frames"] == {}
    report = json.loads(hycosim("report", str(batched), "--json").stdout)
    assert report["node_steps"] == json.loads(hycosim("report", str(single), "--json").stdout)["node_steps"]


@given(rates=st.lists(st.sampled_from([1, 2, 3, 4, 5, 6, 10, 20, 50, 100, 300, 1000]), min_size=1, max_size=4),
       links=st.lists(st.tuples(st.integers(0, 3), st.integers(0, 3)), max_size=5), data=st.data())
def test_a_release_spans_only_base_steps_in_which_no_input_any_node_steps_on_changes(rates, links, data):
    """The span batch_span gives: every link's exchange period (the slower end's step) is a
    multiple of it, every rate divides it or is a multiple of it, it fits MAX_BATCH, and on the
    low-latency transport each node's BATCH (a list of outputs per step of its) fits a frame."""
    from hycosim.core.coupling import BATCH_BYTES
    from hycosim.core.frames import MAX_BATCH

    names = [f"n{i}" for i in range(len(rates))]
    links = sorted({(s % len(rates), d % len(rates)) for s, d in links})
    widths = [data.draw(st.sampled_from([1, 1, 40, 400])) for _ in rates]
    nodes = [{"nodeName": n, "UID": i + 1, "model": "gain", "input": [f"u{j}" for j in range(len(rates))],
              "output": ["y", *(f"z{j}" for j in range(w - 1))], "stepSize": m * 0.001}
             for i, (n, m, w) in enumerate(zip(names, rates, widths))]
    cosim = {"stepSize": 0.001, "stopTime": 1.0, "batchReleases": data.draw(st.booleans()),
             "lowLatency": data.draw(st.booleans()), "realTime": data.draw(st.sampled_from([False, False, True, 2.0]))}
    doc = {"nodeNum": len(nodes), "nodeLists": nodes, "linkNum": len(links), "coSimulation": cosim,
           "linkLists": [{"from": f"n{s}.y", "to": f"n{d}.u{s}"} for s, d in links]}
    plan = parse_project(doc, "p.json").coupling
    span = plan.batch
    assert 1 <= span <= MAX_BATCH
    assert all(max(rates[s], rates[d]) % span == 0 for s, d in links)
    assert all(span % m == 0 or m % span == 0 for m in rates)
    if cosim["lowLatency"] and span > 1:
        assert all(-(-span // m) * (4 + 9 * w) <= BATCH_BYTES for m, w in zip(rates, widths))
    if not cosim["batchReleases"] or max(rates) == 1 or cosim["realTime"]:
        assert span == 1  # off, single-rate, or paced: every base point released at its wall time
    elif not links and all(m == rates[0] for m in rates) and rates[0] <= MAX_BATCH and max(widths) == 1:
        assert span == rates[0]  # unlinked nodes of one rate: a release per step of theirs


def _chain(tmp_path: Path, coupling: str, order: list[str] | None = None) -> Path:
    cosim = {"stepSize": 0.1, "stopTime": 1.0, "coupling": coupling}
    if order:
        cosim["order"] = order
    # Listed out of order: Gauss-Seidel derives a → b → c from the links.
    return write_project(tmp_path / f"{coupling}.json", [
        {"nodeName": "c", "UID": 3, "model": "gain", "input": ["u"], "output": ["y"]},
        {"nodeName": "a", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "b", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "a.y", "to": "b.u"}, {"from": "b.y", "to": "c.u"}], cosim=cosim)


def test_gauss_seidel_steps_each_node_on_its_predecessors_new_outputs(tmp_path):
    jacobi = read_rows(run_project(_chain(tmp_path, "jacobi"), tmp_path / "j"))
    gs_run = run_project(_chain(tmp_path, "gauss-seidel"), tmp_path / "gs")
    gs = read_rows(gs_run)
    a = column(gs, "a.y")
    # Jacobi: each link delays by one macro step; Gauss-Seidel: none along the order.
    assert column(jacobi, "c.y")[2:] == pytest.approx(column(jacobi, "a.y")[:-2])
    assert column(gs, "c.y") == pytest.approx(a) and column(gs, "b.y") == pytest.approx(a)
    # Each row's inputs are those the nodes stepped on from that point (the last row's: routed there).
    assert column(gs, "b.u")[:-1] == pytest.approx(a[1:]) and column(gs, "c.u")[:-1] == pytest.approx(a[1:])
    assert meta(gs_run)["coupling"] == "Gauss-Seidel, order a → b → c"


def test_gauss_seidel_on_a_cycle_follows_the_given_order(tmp_path):
    """x and y read each other: the order breaks the cycle, y reads x's new outputs, x y's old."""
    nodes = [{"nodeName": n, "UID": i, "model": "gain", "parameters": {"k": 0.5}, "input": ["u"], "output": ["y"]}
             for i, n in enumerate(("x", "y"), 1)]
    nodes.append({"nodeName": "src", "UID": 3, "model": "ramp", "output": ["y", "v"]})
    links = [{"from": "y.y", "to": "x.u"}, {"from": "x.y", "to": "y.u"}]
    cosim = {"stepSize": 0.1, "stopTime": 0.5, "coupling": "gauss-seidel"}
    cfg = write_project(tmp_path / "cycle.json", nodes, links, cosim=cosim)
    res = hycosim("validate", str(cfg))
    assert res.returncode == 2
    assert "coSimulation.order: the links make a cycle among x, y" in res.stderr
    cfg = write_project(tmp_path / "cycle.json", nodes, links, cosim={**cosim, "order": ["y", "x", "src"]})
    rows = read_rows(run_project(cfg, tmp_path / "runs"))
    x, y = column(rows, "x.y"), column(rows, "y.y")
    for k in range(len(rows) - 1):
        assert float(rows[k]["y.u"]) == pytest.approx(x[k])  # y first: x's output at the step's start
        assert float(rows[k]["x.u"]) == pytest.approx(y[k + 1])  # then x, on y's new output


@pytest.mark.parametrize("cosim, nodes_extra, expected", [
    ({}, {"stepSize": 0.015}, "nodeLists[1].stepSize: node 'b' steps 0.015 s, which is not an integer multiple "
                              "of coSimulation.stepSize 0.01 s"),
    ({"eventTolerance": 0.001}, {"stepSize": 0.02}, "coSimulation.eventTolerance: locating events by rollback "
                                                    "works with single-rate nodes only; b steps slower"),
    ({"order": ["a", "b"]}, {}, "coSimulation.order: an order is for Gauss-Seidel coupling"),
    ({"coupling": "gauss-seidel", "order": ["a", "z"]}, {}, "coSimulation.order: names 'z', which is not a "
                                                             "stepping node"),
    ({"coupling": "gauss-seidel", "order": ["a"]}, {}, "coSimulation.order: leaves out b"),
    ({"coupling": "gauss-seidel", "order": ["a", "b", "a"]}, {}, "coSimulation.order: names a more than once"),
    ({"coupling": "gauss-seidel"}, {"stepSize": 0.02}, "coSimulation.coupling: Gauss-Seidel coupling works with "
                                                       "single-rate nodes only; b"),
    ({"coupling": "gauss-seidel", "eventTolerance": 0.001}, {}, "coSimulation.eventTolerance: locating events "
                                                                "by rollback works with Jacobi coupling only"),
    ({"coupling": "gauss-jordan"}, {}, "coSimulation.coupling"),
    ({}, {"stepSize": -0.02}, "nodeLists[1].stepSize"),
])
def test_bad_coupling_settings_are_named_by_validate(tmp_path, cosim, nodes_extra, expected):
    cfg = write_project(tmp_path / "bad.json", [
        {"nodeName": "a", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "b", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"], **nodes_extra},
    ], [{"from": "a.y", "to": "b.u"}], cosim={"stepSize": 0.01, "stopTime": 0.1, **cosim})
    res = hycosim("validate", str(cfg))
    assert res.returncode == 2 and expected in res.stderr, res.stderr
    assert "Traceback" not in res.stderr


def test_an_asynchronous_source_has_no_step_size_and_decimal_multiples_are_accepted():
    doc = {"nodeNum": 2, "nodeLists": [
        {"nodeName": "cam", "UID": 1, "model": "camera", "async": True, "rate": 30, "stepSize": 0.1, "output": ["a"]},
        {"nodeName": "b", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"], "stepSize": 0.3}],
        "coSimulation": {"stepSize": 0.1}}
    with pytest.raises(ConfigError) as info:
        parse_project(doc)
    assert "nodeLists[0].stepSize: asynchronous node 'cam' does not step" in str(info.value)
    del doc["nodeLists"][0]["stepSize"]
    loaded = parse_project(doc)  # 0.3 / 0.1 is 2.9999999999999996 in floats: still a multiple of 3
    assert loaded.coupling.rates == {"b": 3}


_NAMES = ["a", "b", "c", "cam", "z"]
_STEPS = st.none() | st.floats(allow_nan=False, allow_infinity=False) | st.sampled_from([0.01, 0.02, 0.3, 1e308])


@st.composite
def _coupled_projects(draw) -> dict:
    """Project files whose coupling keys are anything JSON can hold, mostly near the valid ones."""
    nodes = [{"nodeName": n, "UID": i, "model": "gain", "input": ["u"], "output": ["y"]}
             for i, n in enumerate(["a", "b", "c"], 1)]
    nodes.append({"nodeName": "cam", "UID": 4, "model": "camera", "async": True, "rate": 30, "output": ["y"]})
    for node in nodes:
        step = draw(_STEPS)
        if step is not None:
            node["stepSize"] = step
    links = draw(st.lists(st.tuples(st.sampled_from(["a", "b", "c", "cam"]), st.sampled_from(["a", "b", "c"])),
                          max_size=4, unique_by=lambda pair: pair[1]))
    cosim = {"stepSize": draw(st.sampled_from([0.01, 0.1, 1e-10])), "stopTime": 1.0}
    if draw(st.booleans()):
        cosim["coupling"] = draw(st.sampled_from(["jacobi", "gauss-seidel"]) | st.text(max_size=5) | st.integers())
    if draw(st.booleans()):
        cosim["order"] = draw(st.lists(st.sampled_from(_NAMES), max_size=5) | st.integers() | st.text(max_size=3))
    if draw(st.booleans()):
        cosim["eventTolerance"] = 0.001
    numbers = st.sampled_from([0.001, 0.1, 0.0, -1.0, 2.0, 1e308]) | st.integers(-2, 3) | st.text(max_size=2)
    if draw(st.booleans()):
        cosim["iterate"] = draw(st.fixed_dictionaries({"tolerance": numbers}, optional={
            "maxIterations": numbers, "relaxation": numbers, "onFailure": st.sampled_from(["continue", "stop", "x"]),
            "interpolate": numbers}))
    if draw(st.booleans()):
        cosim["stepControl"] = draw(st.fixed_dictionaries({}, optional={
            "tolerance": numbers, "minStep": numbers, "maxStep": numbers}) | st.integers())
    return {"nodeNum": 4, "nodeLists": nodes, "linkNum": len(links),
            "linkLists": [{"from": f"{src}.y", "to": f"{dst}.u"} for src, dst in links], "coSimulation": cosim}


@given(_coupled_projects())
def test_coupling_keys_give_a_plan_or_errors_that_name_them(doc):
    try:
        loaded = parse_project(doc, "p.json")
    except ConfigError as exc:
        assert exc.issues and all(i.path for i in exc.issues)
        return
    c, base = loaded.coupling, doc["coSimulation"]["stepSize"]
    cosim = loaded.project.coSimulation
    if cosim.stepControl is not None:
        assert 0 < cosim.stepControl.minStep <= cosim.stepControl.maxStep and cosim.iterate is None
    if cosim.iterate is not None or cosim.stepControl is not None:  # steps taken again: single-rate Jacobi
        assert c.scheme == "jacobi" and not c.multirate and cosim.eventTolerance is None
    if cosim.iterate is not None:
        assert type(cosim.iterate.interpolate) is int and 0 <= cosim.iterate.interpolate <= 3
    assert sorted(c.rates) == ["a", "b", "c"] and sorted(c.order) == ["a", "b", "c"]
    for node in doc["nodeLists"][:3]:
        m = c.rates[node["nodeName"]]
        assert type(m) is int and m >= 1
        assert math.isclose(m * base, node.get("stepSize", base), rel_tol=1e-8)
    if c.scheme == "gauss-seidel":
        assert not c.multirate
        placed = {n: i for i, n in enumerate(c.order)}
        if "order" not in doc["coSimulation"]:  # derived: a node after the nodes it reads from
            for link in doc["linkLists"]:
                src, dst = link["from"].split(".")[0], link["to"].split(".")[0]
                if src != "cam" and src != dst:
                    assert placed[src] < placed[dst]


def _recovering(tmp_path: Path, **extra) -> Path:
    nodes = [
        {"nodeName": "rod", "UID": 1, "model": "hycosim.scenario.rod.node:RodNode", "parameters": {"initial_angle_deg": 35},
         "output": ["angle", "omega"]},
        {"nodeName": "g1", "UID": 2, "model": "gain", "parameters": {"k": 2.0}, "input": ["u"], "output": ["y"]},
        {"nodeName": "g2", "UID": 3, "model": "gain", "parameters": {"k": 0.5, "work_s": 0.003}, "input": ["u"],
         "output": ["y"]},
    ]
    for node in nodes:
        node.update(extra.pop(node["nodeName"], {}))
    cosim = {"stepSize": 0.01, "stopTime": 4.0, "attachTimeout": 20.0, "checkpointEvery": 0.5, **extra}
    links = [{"from": "rod.angle", "to": "g1.u"}, {"from": "g1.y", "to": "g2.u"}]
    return write_project(tmp_path / "p.json", nodes, links, cosim=cosim, name="rec")


@pytest.mark.parametrize("setting, victim", [
    ({"g2": {"stepSize": 0.07}}, "node g2"),  # checkpoints at 0.7 s steps: every 7th base point at most
    ({"coupling": "gauss-seidel"}, "node g1"),
    ({"iterate": {"tolerance": 1e-9}, "stopTime": 2.5}, "node g2"),
])
def test_checkpoints_restore_multi_rate_gauss_seidel_and_iterated_runs_to_what_they_record_unkilled(tmp_path, setting, victim):
    (tmp_path / "ref").mkdir()
    reference = (run_project(_recovering(tmp_path / "ref", **setting), tmp_path / "ref" / "runs")
                 / "values.csv").read_bytes()
    killed = _recovering(tmp_path, **setting)
    code, err = run_killing(killed, tmp_path / "runs", [(victim, 180)])
    assert code == 0, err
    run = next((tmp_path / "runs").iterdir())
    assert (run / "values.csv").read_bytes() == reference
    m = meta(run)
    assert [(r["node"], r["cause"]) for r in m["recoveries"]] == [(victim.split()[1], "restarted")]
    period = 7 if "g2" in setting else 1
    assert all(r["restored"] % period == 0 for r in m["recoveries"])
    if "iterate" in setting:  # the chain rod → g1 → g2 settles in three takes of each step
        assert m["iterations"]["max_takes"] == 3 and m["iterations"]["not_converged"] == 0


def test_a_forged_batch_of_another_number_of_steps_is_dropped_and_the_run_records_the_same(tmp_path):
    """On a project without credentials anyone may write on a node's key: a BATCH with the node's
    UID and the batch's label but one step's outputs where the release asked for ten is dropped
    ("wrong step"), counted, and the run records what it records unforged."""
    import queue
    import threading

    import zenoh

    from hycosim.core import frames
    from hycosim.transport.keys import ProjectKeys
    from hycosim.transport.session import client_config
    from tests.helpers import free_endpoint, reap, recorded_rows, spawn, wait_for

    def project(name: str, endpoint: str) -> Path:
        cfg = write_project(tmp_path / f"{name}.json", [
            {"nodeName": "fast", "UID": 1, "model": "ramp", "output": ["y", "v"]},
            {"nodeName": "mid", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"], "stepSize": 0.1,
             "parameters": {"work_s": 0.05}},
        ], [{"from": "fast.y", "to": "mid.u"}], cosim={"stepSize": 0.01, "stopTime": 5.0}, name="forge")
        doc = json.loads(cfg.read_text())
        doc["serverIP"] = endpoint
        cfg.write_text(json.dumps(doc))
        return cfg

    clean = run_project(project("clean", free_endpoint()), tmp_path / "clean")
    endpoint, keys = free_endpoint(), ProjectKeys("forge")
    proc = spawn("run", str(project("forged", endpoint)), "--runs-dir", str(tmp_path / "runs"), "--no-progress",
                 "--listen", endpoint)
    releases: queue.Queue = queue.Queue()
    forged: list[int] = []
    try:
        wait_for(lambda: recorded_rows(tmp_path / "runs") > 0, 60, "the run's first rows")
        with zenoh.open(client_config(endpoint)) as session:
            sub = session.declare_subscriber(keys.down, lambda s: releases.put(s.payload.to_bytes()))

            def forge() -> None:
                while (payload := releases.get()) is not None:
                    release = frames.decode(payload)
                    if release.kind == frames.STEPS:
                        session.put(keys.up("fast"), frames.encode(frames.BATCH, 1, release.step + 1,
                                                                   release.times[-1], [0.0, 1.0], []))
                        forged.append(release.step)

            forger = threading.Thread(target=forge)
            forger.start()
            _, err = proc.communicate(timeout=120)
            releases.put(None)
            forger.join(timeout=10)
            sub.undeclare()
    finally:
        reap(proc)
    assert proc.returncode == 0, err
    run = next((tmp_path / "runs").iterdir())
    assert forged and meta(run)["dropped_frames"].get("wrong step", 0) >= 1
    assert meta(run)["coupling"].endswith("releases batched over 10 base steps")
    assert (run / "values.csv").read_bytes() == (clean / "values.csv").read_bytes()
