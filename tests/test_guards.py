from __future__ import annotations

import pytest

from core.guards import Guard, GuardError


def test_guard_evaluates_comparisons_logic_and_functions():
    g = Guard("abs(a.x - b.y) < 0.1 and not a.flag or max(a.x, 2) >= 3")
    assert g.references == [("a", "x"), ("b", "y"), ("a", "flag")]
    assert g.holds({("a", "x"): 1.0, ("b", "y"): 1.05, ("a", "flag"): False})
    assert not g.holds({("a", "x"): 1.0, ("b", "y"): 1.05, ("a", "flag"): True})
    assert g.holds({("a", "x"): 3.0, ("b", "y"): 0.0, ("a", "flag"): True})
    assert Guard("0 < a.x <= 1").holds({("a", "x"): 1.0})
    assert not Guard("0 < a.x <= 1").holds({("a", "x"): 0.0})
    assert Guard("a.n == 2").inputs({("a", "n"): 2}) == {"a.n": 2}


@pytest.mark.parametrize("text", ["a.x.y > 1", "x > 1", "open('f')", "a.x if 1 else 2", "'s' == a.x",
                                  "[1][0] > a.x", "a.x >", "lambda: 1"])
def test_guard_rejects(text):
    with pytest.raises(GuardError):
        Guard(text)
