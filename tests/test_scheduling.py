"""coSimulation.nodeScheduling: which runs schedule their nodes as batch work, and a node's
process (every thread of it, Zenoh's included) scheduled so by the kernel."""

from __future__ import annotations

import os

import pytest

from hycosim.core.config import load_project
from hycosim.core.scheduling import batch_nodes
from tests.helpers import column, read_rows, run_project, write_project


@pytest.mark.parametrize("policy, processes, cpus, paced, batch", [
    ("auto", 9, 2, False, True),  # more processes than cores
    ("auto", 3, 2, False, True),
    ("auto", 2, 2, False, False),  # a core each: a woken node has a core of its own to go to
    ("auto", 9, 16, False, False),
    ("auto", 9, None, False, True),  # cores unknown: taken as one
    ("auto", 9, 2, True, False),  # paced to the wall clock: a wake-up's latency matters
    ("batch", 2, 16, True, True),  # asked for: always
    ("normal", 9, 2, False, False),
])
def test_which_runs_schedule_their_nodes_as_batch_work(policy, processes, cpus, paced, batch):
    assert batch_nodes(policy, processes, cpus, paced) is batch


def _project(tmp_path, **cosim):
    settings = {"stepSize": 0.01, "stopTime": 0.05, **cosim}
    return write_project(tmp_path / "p.json", [
        {"nodeName": "s", "UID": 1, "model": "tests.nodes:Scheduling", "output": ["policy", "others"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "s.policy", "to": "g.u"}], cosim=settings)


def test_a_project_pacing_its_run_or_with_an_asynchronous_source_keeps_the_default_policy(tmp_path):
    # Two nodes and the server: three processes, more than one core has.
    assert load_project(_project(tmp_path)).project.batch_nodes(1)
    assert not load_project(_project(tmp_path, realTime=True)).project.batch_nodes(1)
    assert load_project(_project(tmp_path, realTime=0.0)).project.batch_nodes(1)  # as fast as it goes
    assert not load_project(_project(tmp_path, nodeScheduling="normal")).project.batch_nodes(1)
    assert load_project(_project(tmp_path, nodeScheduling="batch")).project.batch_nodes(64)
    doc = load_project(_project(tmp_path)).project.model_dump(by_alias=True, exclude_none=True)
    doc["nodeLists"].append({"nodeName": "cam", "UID": 3, "model": "sine_source", "async": True, "rate": 20.0,
                             "output": ["y"]})
    with_source = write_project(tmp_path / "q.json", doc["nodeLists"], doc["linkLists"], cosim=doc["coSimulation"])
    assert not load_project(with_source).project.batch_nodes(1)


@pytest.mark.skipif(not hasattr(os, "SCHED_BATCH"), reason="Linux's scheduling policies")
@pytest.mark.parametrize("setting, policy", [("batch", "SCHED_BATCH"), ("normal", "SCHED_OTHER")])
def test_a_node_process_and_every_thread_of_it_run_under_the_policy_its_project_gives(tmp_path, setting, policy):
    run = run_project(_project(tmp_path, nodeScheduling=setting), tmp_path / "runs")
    rows = read_rows(run)
    stepped = rows[1:]  # the first row holds the outputs before any step
    assert stepped and column(stepped, "s.policy") == [getattr(os, policy)] * len(stepped)
    assert column(stepped, "s.others") == [0] * len(stepped)
    said = (run / "node-s.log.jsonl").read_text()
    assert ('"policy": "batch"' in said) is (setting == "batch")
