"""The master's parts through their own interfaces: the releases' ledger (hycosim.master.ledger:
which step each node owes after a release, at which point, and what each answer is to the point
being gathered), event localisation's bisection (hycosim.master.localisation), and the step
strategies that take a step again (hycosim.master.retakes: iterative coupling, the
error-controlled step)."""

from __future__ import annotations

import math

from hypothesis import given, strategies as st

from hycosim.core.frames import Batch, End, Outputs
from hycosim.core.schema import Iterate, StepControl
from hycosim.master.ledger import ENDED, LATER, TAKE, Ledger, Refusal
from hycosim.master.retakes import StepSizer, control_step, input_change, iterate_step, relaxed

NODES = ["a", "b", "c", "d"]


def _outputs(step: int) -> Outputs:
    return Outputs(1, step, 0.0, [1.0])


def _batch(step: int, before: int) -> Batch:
    return Batch(1, step, 0.0, [1.0], [[0.5]] * before)


def _end(step: int) -> End:
    return End(1, step, 0.0, True, "done", [], None)


rates = st.lists(st.integers(1, 5), min_size=1, max_size=len(NODES)).map(lambda r: dict(zip(NODES, r)))


@given(rates=rates, k=st.integers(0, 50), left=st.integers(1, 8))
def test_a_release_makes_each_node_due_at_the_end_of_its_own_step_and_sorts_its_answer_there(rates, k, left):
    """Released from point k, a node of rate m owes its outputs labelled k + 1 at point k + m (at
    most the last point). Gathering k + 1, a node due there is taken; a slower one's answer is
    kept for its point, handed over there once, and a second copy of it is a duplicate."""
    ledger = Ledger(list(rates), [], rates)
    last_point = k + left
    ledger.released(list(rates), k, 0.0, last_point=last_point)
    due_at = {n: k + 1 if m == 1 else min(k + m, last_point) for n, m in rates.items()}
    for point in range(k + 1, last_point + 1):
        assert ledger.due(point) == {n for n, at in due_at.items() if at == point}
    pending = ledger.due(k + 1)
    for node in rates:
        verdict = ledger.sort(node, _outputs(k + 1), k + 1, pending)
        assert verdict == (TAKE if due_at[node] == k + 1 else LATER)
        if verdict is LATER:
            ledger.keep(node, _outputs(k + 1))
            again = ledger.sort(node, _outputs(k + 1), k + 1, pending)
            assert isinstance(again, Refusal) and again.reason == "duplicate"
    for point in range(k + 2, last_point + 1):
        kept = ledger.kept_for(ledger.due(point))
        assert [n for n, _ in kept] == sorted(n for n, at in due_at.items() if at == point)
        assert all(frame.step == k + 1 for _, frame in kept)
        assert ledger.kept_for(ledger.due(point)) == []  # handed over once


@given(rates=rates, k=st.integers(0, 50), off=st.integers(-3, 3).filter(bool),
       kind=st.sampled_from(["outputs", "batch", "end"]))
def test_an_answer_with_another_label_is_refused_whatever_its_kind(rates, k, off, kind):
    ledger = Ledger(list(rates), [], rates)
    ledger.released(list(rates), k, 0.0)
    step = k + 1 + off
    frame = _outputs(step) if kind == "outputs" else _batch(step, 0) if kind == "batch" else _end(step)
    for node in rates:
        verdict = ledger.sort(node, frame, k + 1, set(rates))
        assert verdict == Refusal("step already past" if off < 0 else "wrong step",
                                  f"{node} sent step {step} while collecting {k + 1}")
    assert ledger.sort(NODES[0], _end(k + 1), k + 1, set(rates)) is ENDED


@given(rates=rates, k=st.integers(0, 50), count=st.integers(2, 12), before=st.integers(0, 12))
def test_a_batched_release_takes_one_batch_of_each_nodes_steps_inside_it(rates, k, count, before):
    """Over ``count`` base steps, a node of rate m ≤ the span owes one BATCH at the release's end
    holding its outputs after each of its steps before its last; an OUTPUTS, or a BATCH of
    another number of steps, is refused by name."""
    span = max(count, *rates.values())
    ledger = Ledger(list(rates), [], rates)
    ledger.released(list(rates), k, 0.0, count=count, batched=True, span=span)
    assert ledger.due(k + count) == set(rates)
    for node, m in rates.items():
        owed = len(range(0, count, m)) - 1
        verdict = ledger.sort(node, _batch(k + 1, before), k + count, set(rates))
        if before == owed:
            assert verdict is TAKE
        else:
            assert verdict == Refusal("wrong step", f"{node} sent the outputs of {before + 1} steps for a batch "
                                      f"of {owed + 1} of its steps")
        refused = ledger.sort(node, _outputs(k + 1), k + count, set(rates))
        assert isinstance(refused, Refusal) and refused.reason == "wrong kind"
    # The next release, unbatched, owes OUTPUTS again.
    ledger.released(list(rates), k + count, 0.0)
    assert ledger.sort(NODES[0], _batch(k + count + 1, 0), k + count + 1, set(rates)).reason == "wrong kind"


@given(step=st.integers(0, 100))
def test_a_start_or_restore_forgets_what_was_kept_and_batched(step):
    rates = {"a": 1, "b": 3}
    ledger = Ledger(list(rates), [], rates)
    ledger.released(["a", "b"], 10, 0.0, count=3, batched=True, span=3)
    ledger.keep("b", _batch(11, 0))
    ledger.expect_all(step, 0.0)
    assert ledger.kept_for({"a", "b"}) == []
    assert ledger.due(step) == {"a", "b"}
    assert all(ledger.sort(n, _outputs(step), step, {"a", "b"}) is TAKE for n in rates)


@given(step=st.integers(0, 100))
def test_a_played_source_answers_each_point_with_its_own_step_once(step):
    ledger = Ledger(["a"], ["src"], {"a": 1})
    assert ledger.label("src", step) == step
    assert ledger.sort("src", _outputs(step), step, {"a", "src"}) is TAKE
    assert ledger.sort("src", _outputs(step), step, {"a"}).reason == "duplicate"
    assert ledger.sort("src", _outputs(step + 1), step, {"src"}).reason == "wrong step"


@given(h=st.floats(1e-3, 10.0), share=st.floats(1e-6, 1.0), tol=st.floats(1e-6, 1.0))
def test_a_crossing_is_bisected_to_within_the_tolerance_and_the_last_step_taken_ends_after_it(h, share, tol):
    """The guard starts to hold at c inside (0, h]: the window found holds c, is at most the
    tolerance wide, was found in the fewest halvings, and the nodes stand at its end."""
    from hycosim.master.localisation import bisect_crossing

    c = h * share
    taken: list[float] = []

    def take(length: float) -> bool:
        taken.append(length)
        return length >= c

    at = bisect_crossing(h, tol, take)
    assert at.lo < c <= at.hi and at.hi - at.lo <= tol
    assert at.tries == len(taken)
    assert (taken[-1] if taken else h) == at.hi
    halvings = max(0, math.ceil(math.log2(h / tol)))  # each halves the window, from h
    assert halvings - 1 <= len(taken) <= halvings + 2  # (+1: the step taken again at hi; ±1: rounding)


@given(a=st.floats(-1.5, 1.5), b=st.floats(-10, 10), u0=st.floats(-10, 10), tolerance=st.floats(1e-9, 1e-2),
       relaxation=st.floats(0.1, 1.0), most=st.integers(2, 30))
def test_an_iterated_step_is_taken_again_on_relaxed_inputs_until_they_settle_or_its_takes_run_out(
        a, b, u0, tolerance, relaxation, most):
    """A node whose step on input u ends with output a·u + b, fed back to u: each take after the
    first is on the routed end value relaxed towards the input the step was last taken on; the
    step stops at the first take whose end changed the input by at most the tolerance, or at
    maxIterations, and says which."""
    settings = Iterate(tolerance=tolerance, relaxation=relaxation, maxIterations=most)
    labels = {"n": ["n.u"]}
    taken = [{"n": [u0]}]  # the inputs of every take, the first's given

    def end_of(used):
        candidate = {"n": [a * used["n"][0] + b]}
        return (candidate, *input_change(candidate, used, labels, tolerance))

    def measure(used):
        assert used is taken[-1]  # measured from the end of the last take
        return end_of(used)

    settled = iterate_step(taken[0], measure, taken.append, settings)
    assert settled.takes == len(taken) <= most and settled.used is taken[-1]
    changes = [end_of(u)[1] for u in taken]
    assert all(c > 1.0 for c in changes[:-1])  # no take before the last had settled
    assert settled.converged == (changes[-1] <= 1.0) and settled.change == changes[-1]
    assert settled.converged or settled.takes == most
    for before, after in zip(taken, taken[1:]):
        assert after == relaxed(end_of(before)[0], before, relaxation)
    if settled.converged and changes[-1] > 0:
        assert settled.port == "n.u"


@given(c=st.floats(0.0, 1e6), h=st.floats(1e-3, 1.0), min_step=st.floats(1e-4, 1e-2), tolerance=st.floats(1e-6, 1.0))
def test_a_controlled_step_is_taken_again_shorter_until_its_error_is_within_the_tolerance_or_at_min_step(
        c, h, min_step, tolerance):
    """Over a step of length L the inputs change c·L (in tolerances): each retake is shorter than
    the one before and is asked for because the error change·L/2 of the one before was above 1 at
    a length above minStep; the length that stands is the last one taken."""
    sizer = StepSizer.starting(StepControl(tolerance=tolerance, minStep=min_step, maxStep=1.0), h)
    lengths = [sizer.h]
    stood, takes = control_step(sizer.h, lambda: c * lengths[-1], lengths.append, sizer)
    assert takes == len(lengths) and stood == lengths[-1]
    for before, after in zip(lengths, lengths[1:]):
        assert after < before and c * before * before / 2 > 1.0 and before > min_step
    error = c * stood * stood / 2
    assert error <= 1.0 or stood <= min_step * (1 + 1e-9)
    assert sizer.rejected == takes - 1 and sizer.accepted == 1 and min_step <= sizer.h <= 1.0
