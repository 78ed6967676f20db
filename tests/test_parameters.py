"""A node entry's parameter values are checked when its model is loaded (``hycosim validate``
and every run), as their names are: what the loader takes, the model sets up and steps with;
what it refuses is named with the node and the parameter."""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hycosim.node.loader import NodeLoadError, model_class
from hycosim.node.interface import AsyncSource, NodeContext
from hycosim.core.schema import Node as NodeSpec
from tests.helpers import hycosim, write_project

# Each checked model, with values a user might write for its parameters: plausible numbers
# (the defaults' scale), numbers that are not (signs, zero, the far ends of floats), and what
# is no number at all.
_PLAUSIBLE = st.floats(0.001, 5.0)
_NUMBERS = st.one_of(_PLAUSIBLE, _PLAUSIBLE, _PLAUSIBLE, st.floats(-5.0, 5.0), st.integers(-3, 3),
                     st.sampled_from([0.0, 1e-300, 1e300, -1e300]))
_WRONG = st.sampled_from([math.nan, math.inf, -math.inf, True, False, None, "1.0", "0.6 m", [], {}, [1.0, 2.0], 1.5])
_POINTS = st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3)
_POSES = st.lists(st.floats(-400.0, 400.0) | st.integers(-200, 200), min_size=6, max_size=6)
_SPECIAL = {"pivot": _POINTS, "base": _POINTS, "check_reach": st.booleans(), "q0_deg": _POSES,
            "micro_steps": st.integers(-2, 50), "rate": st.floats(-10.0, 200.0),
            "work_s": st.floats(-1.0, 0.001)}  # (the gain sleeps that long a step)
_MODELS = ["gain", "ramp", "ramp_source", "pendulum", "bouncing_ball", "rod", "robot"]


@st.composite
def _entries(draw, model: str) -> dict:
    cls = model_class(NodeSpec.model_validate({"nodeName": "n", "UID": 1, "model": model,
                                               "async": model == "ramp_source"}))
    names = draw(st.lists(st.sampled_from(sorted(cls.PARAMETERS)), unique=True, max_size=4))
    return {name: draw(st.one_of(*[_SPECIAL.get(name, _NUMBERS)] * 4, _WRONG)) for name in names}


@pytest.mark.parametrize("model", _MODELS)
@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_parameters_the_loader_takes_set_the_model_up_and_those_it_refuses_are_named(model, data, tmp_path_factory):
    parameters = data.draw(_entries(model))
    spec = NodeSpec.model_validate({"nodeName": "arm", "UID": 1, "model": model, "async": model == "ramp_source",
                                    "parameters": parameters})
    try:
        cls = model_class(spec)
    except NodeLoadError as exc:
        text = str(exc)
        assert text.startswith("node 'arm': ") and any(f"'{name}'" in text for name in parameters), text
        return
    impl = cls()
    impl.setup(NodeContext("arm", 1, [], [], dict(parameters), 0.01, 0.0, tmp_path_factory.getbasetemp(),
                           stop_time=1.0))
    try:
        if isinstance(impl, AsyncSource):
            produced = [v for _, sample in impl.samples_until(0.1) for v in sample.values()]
        else:
            impl.step(0.0, 0.01, {name: 0.0 for name in cls.INPUTS or ()})
            produced = list(impl.outputs().values())
    finally:
        impl.teardown()
    assert all(math.isfinite(v) for v in produced if isinstance(v, float)), (parameters, produced)


def test_validate_and_run_name_a_parameter_whose_value_no_model_can_take(tmp_path):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "rod", "UID": 1, "model": "rod", "parameters": {"length": -0.6, "pivot": [0.6, 0.0]},
         "output": ["angle"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "parameters": {"k": "2"}, "input": ["u"], "output": ["y"]}],
        [{"from": "rod.angle", "to": "g.u"}], cosim={"stepSize": 0.01, "stopTime": 0.1})
    res = hycosim("validate", str(cfg))
    assert res.returncode == 2 and "Traceback" not in res.stderr
    text = res.stderr.replace("\n", " ")
    assert "node 'rod': model 'rod': parameter 'length' is -0.6; it must be at least 0.001; parameter 'pivot' is " \
           "[0.6, 0.0], not three finite numbers" in text
    assert "node 'g': model 'gain': parameter 'k' is \"2\", not a finite number" in text
    res = hycosim("run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress")
    assert res.returncode == 3 and "parameter 'length' is -0.6" in res.stderr and "Traceback" not in res.stderr
