"""What a run takes up from its project's asks, given what its nodes said in their HELLOs.

The capabilities and the ports a HELLO lists come off the network: any value may stand where a
node's runtime writes a bool or a list of ``name:Type``. The plans take up an ask only when
every stepping node said the JSON ``true`` it needs, and name the others; the port check names
what differs, bounded, whatever was sent.
"""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from hycosim.core.schema import CoSimulation, Iterate, Node, StepControl
from hycosim.master import plans
from hycosim.master.intake import port_mismatch
from hycosim.master.plain_loop import plain_plan
from tests.wire_strategies import values

CAPABILITIES = ["rollback", "variableStep", "serialize", "interpolates"]
NODES = ["a", "b", "clock", "g"]

# What one node said: each capability true, false or anything, sometimes missing, among other keys.
said_by_one = st.dictionaries(st.sampled_from(CAPABILITIES), st.booleans() | values, max_size=4).flatmap(
    lambda caps: st.dictionaries(st.text(max_size=6) | st.integers(-3, 3), values, max_size=2).map(
        lambda extra: {**extra, **caps}))
said_by_all = st.lists(st.sampled_from(NODES), min_size=1, max_size=4, unique=True).flatmap(
    lambda nodes: st.fixed_dictionaries({n: said_by_one for n in nodes}))


def _cosim(**asks) -> CoSimulation:
    return CoSimulation.model_validate({"stopTime": 1.0, "stepSize": 0.01, **asks})


def _named(words: str, nodes: list[str]) -> bool:
    return all(n in words for n in nodes)


@given(said_by_all, st.sampled_from([None, 1e-3]), st.sampled_from([None, 0.25]))
def test_localisation_and_checkpoints_are_taken_up_only_when_every_node_said_true(said, tolerance, every):
    cosim = _cosim(eventTolerance=tolerance, checkpointEvery=every)
    no_rollback = sorted(n for n, c in said.items() if c.get("rollback") is not True)
    rigid = sorted(n for n, c in said.items() if c.get("variableStep") is False)
    no_state = sorted(n for n, c in said.items() if c.get("serialize") is not True)

    located = plans.localisation(cosim, said)
    assert located.on == (tolerance is not None and not no_rollback and not rigid)
    if tolerance is None:
        assert located.words == "none: fixed macro steps (no eventTolerance)" and located.why == ""
    elif not located.on:
        assert located.words.startswith("none: fixed macro steps (") and _named(located.why, no_rollback + rigid)
        assert located.why in located.words
    else:
        assert located.words == "rollback and bisection to 0.001 s"

    kept = plans.checkpoints(cosim, said)
    assert kept.on == (every is not None and not no_state)
    if every is not None and no_state:
        assert kept.words == f"off: {', '.join(no_state)} cannot serialise their state"
    elif every is not None:
        assert kept.words == "every 0.25 s of simulated time"


@given(said_by_all, st.integers(0, 3), st.sets(st.sampled_from(NODES)))
def test_iteration_interpolates_the_inputs_of_exactly_the_nodes_that_said_so(said, degree, with_inputs):
    it = Iterate(tolerance=1e-6, interpolate=degree)
    has_inputs = {n: n in with_inputs for n in said}
    plan = plans.iteration(it, said, has_inputs)
    no_rollback = sorted(n for n, c in said.items() if c.get("rollback") is not True)
    assert plan.on == (not no_rollback)
    if not plan.on:
        assert plan.why == f"{', '.join(no_rollback)} cannot get and set state" and plan.interpolated == ()
        return
    takes = sorted(n for n, c in said.items() if c.get("interpolates") is True)
    assert list(plan.interpolated) == (takes if degree > 0 else [])
    holds = sorted(n for n in said if n not in takes and n in with_inputs) if degree > 0 else []
    assert list(plan.holding) == holds
    assert ("cannot interpolate its inputs" in plan.words) == bool(holds)
    assert ("interpolated over each step by polynomials of degree" in plan.words) == bool(plan.interpolated)


@given(said_by_all)
def test_step_control_needs_every_node_to_roll_back_and_take_steps_of_any_length(said):
    plan = plans.step_control(StepControl(tolerance=1e-3, minStep=1e-3, maxStep=0.1), 0.01, said)
    ok = all(c.get("rollback") is True and c.get("variableStep") is not False for c in said.values())
    assert plan.on == ok
    assert plan.words.startswith("steps of 0.001 to 0.1 s" if ok else "none: fixed macro steps of 0.01 s (")


def test_a_checkpoint_grid_starts_at_the_start_and_is_taken_again_after_a_restore():
    assert plans.checkpoints(_cosim(), {"a": {"serialize": True}}).words == "off (no checkpointEvery)"
    from hycosim.master.checkpoints import next_time
    assert next_time(0.0, 0.0, 0.25) == 0.25
    assert next_time(0.25, 0.0, 0.25) == 0.5  # at a checkpoint's time: the next one
    assert next_time(0.3, 0.1, 0.25) == 0.35
    assert next_time(0.3, 0.0, None) == float("inf")


_NODE = Node.model_validate({"nodeName": "g", "UID": 1, "model": "gain",
                             "input": [{"name": "u", "type": "Real"}],
                             "output": [{"name": "y", "type": "Real"}, {"name": "on", "type": "Boolean"}]})


_LISTED = st.fixed_dictionaries(
    {}, optional={"input": st.lists(st.sampled_from(["u:Real", "u:Integer", "y:Real"]) | values, max_size=40),
                  "output": st.lists(st.sampled_from(["y:Real", "on:Boolean"]) | values, max_size=40)})
# The server's own lists, with keys a later runtime may add beside them.
_OURS_AND_MORE = st.dictionaries(st.text(max_size=6), values, max_size=2).map(lambda extra: {**extra, **_NODE.wire_ports()})


@given(st.none() | values | _LISTED | _OURS_AND_MORE)
def test_a_nodes_port_list_is_accepted_only_as_the_servers_and_any_other_is_named_boundedly(theirs):
    ours = _NODE.wire_ports()
    differ = port_mismatch(_NODE, theirs)
    fits = theirs is None or (type(theirs) is dict and all(theirs.get(k) == ours[k] for k in ("input", "output")))
    assert (differ is None) == fits
    if differ is not None:
        for kind in ("input", "output"):
            wrong = type(theirs) is not dict or theirs.get(kind) != ours[kind]
            assert (f"its {kind}s are " in differ) == wrong
            if wrong:
                assert f"the server's {', '.join(ours[kind])}" in differ
        assert len(differ) < 2 * (32 * 66 + 200)  # 32 names of at most 64 characters a kind, shown


_PLAIN_ASKS = {"scheme": "GaussSeidel", "events": True, "scenario": True, "sources": True, "checkpoints": True,
               "multirate": True, "span": 4, "calls": True, "paced": True, "held": True}


@given(st.sets(st.sampled_from(sorted(_PLAIN_ASKS))))
def test_the_flat_loop_is_planned_only_where_a_point_is_a_route_and_a_release(asks):
    """plain_plan takes a run's points flat only where none of the things that happen at a
    point besides routing and releasing is asked for, and names each that is."""
    plan = plain_plan(**{key: (value if key in asks else {"scheme": "", "span": 1}.get(key, False))
                         for key, value in _PLAIN_ASKS.items()})
    assert plan.on == (not asks)
    words = {"scheme": "GaussSeidel", "events": "events", "scenario": "a scenario", "sources": "asynchronous sources",
             "checkpoints": "checkpoints", "multirate": "multi-rate", "span": "batched releases",
             "calls": "steps as calls", "paced": "real time", "held": "points held by a caller"}
    assert sorted(w for w in plan.why.split(", ") if w) == sorted(words[a] for a in asks)
