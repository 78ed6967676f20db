"""An FMU's ports read and written in one C call per type (fmi.value_access) give what
fmpy's calls, one variable at a time, give: two instances of one FMU, one driven through each,
stay equal value for value over drawn inputs."""

from __future__ import annotations

import math

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hycosim.fmi.value_access import Port, port_access
from tests.fmi3_fmus import build as build3

_FIXTURES = settings(suppress_health_check=[HealthCheck.function_scoped_fixture])


def _slaves(path, cls, count=2):
    md = read_model_description(str(path))
    unzipped = extract(str(path))
    out = []
    for i in range(count):
        s = cls(guid=md.guid if cls is FMU2Slave else md.instantiationToken, unzipDirectory=unzipped,
                modelIdentifier=md.coSimulation.modelIdentifier, instanceName=f"i{i}")
        s.instantiate()
        if cls is FMU2Slave:
            s.setupExperiment(startTime=0.0)
            s.enterInitializationMode()
        else:
            s.enterInitializationMode(startTime=0.0)
        s.exitInitializationMode()
        out.append(s)
    return md, out


def _pair(path, cls):
    """Two instances of one FMU, torn down after the module's tests."""
    md, instances = _slaves(path, cls)
    yield {v.name: v for v in md.modelVariables}, *instances
    for s in instances:
        s.terminate()
        s.freeInstance()


@pytest.fixture(scope="module")
def types_fmu(tmp_path_factory):
    from benchmarks._small_fmus import build

    yield from _pair(build(tmp_path_factory.mktemp("small"))["Types"], FMU2Slave)


@pytest.fixture(scope="module")
def statespace(tmp_path_factory):
    yield from _pair(build3(tmp_path_factory.mktemp("fmi3"))["statespace"], FMU3Slave)


def _ports(variables, names, sizes=None):
    return [Port(variables[n].valueReference, variables[n].type, (sizes or {}).get(n)) for n in names]


@_FIXTURES
@given(st.lists(st.tuples(st.floats(-1e6, 1e6, allow_nan=False), st.integers(-2**31, 2**31 - 1), st.booleans()),
                min_size=1, max_size=5))
def test_fmi2_ports_of_three_types_read_and_write_as_fmpys_calls_do(types_fmu, steps):
    variables, ours, theirs = types_fmu
    inputs = ["ru", "iu", "bu"]
    outputs = ["ry", "iy", "by"]
    writer = port_access(ours, _ports(variables, inputs), False, True)
    reader = port_access(ours, _ports(variables, outputs), False, False)
    assert writer is not None and reader is not None
    for ru, iu, bu in steps:
        writer.write([ru, iu, bu])
        theirs.setReal([variables["ru"].valueReference], [ru])
        theirs.setInteger([variables["iu"].valueReference], [iu])
        theirs.setBoolean([variables["bu"].valueReference], [bu])
        for s in (ours, theirs):
            s.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.01)
        got = reader.read()
        want = [theirs.getReal([variables["ry"].valueReference])[0],
                int(theirs.getInteger([variables["iy"].valueReference])[0]),
                bool(theirs.getBoolean([variables["by"].valueReference])[0])]
        assert [type(v) for v in got] == [float, int, bool]
        assert got[0] == want[0] or (math.isnan(got[0]) and math.isnan(want[0]))
        assert got[1:] == want[1:]


@_FIXTURES
@given(st.tuples(st.floats(-1e6, 1e6, allow_nan=False), st.integers(-2**31, 2**31 - 1), st.booleans()),
       st.sampled_from([["ry"], ["iy"], ["by"], ["iy", "ry"], ["ry", "ry"]]))
def test_ports_of_one_type_read_in_one_slice_give_what_fmpys_calls_give(types_fmu, given_inputs, outputs):
    # One Real or one Integer call is read as its buffer's slice; an FMI 2 Boolean (a C int)
    # still needs its conversion, and two types two calls.
    variables, ours, theirs = types_fmu
    ru, iu, bu = given_inputs
    port_access(ours, _ports(variables, ["ru", "iu", "bu"]), False, True).write([ru, iu, bu])
    theirs.setReal([variables["ru"].valueReference], [ru])
    theirs.setInteger([variables["iu"].valueReference], [iu])
    theirs.setBoolean([variables["bu"].valueReference], [bu])
    for s in (ours, theirs):
        s.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.01)
    read = {"ry": lambda vr: theirs.getReal([vr])[0], "iy": lambda vr: int(theirs.getInteger([vr])[0]),
            "by": lambda vr: bool(theirs.getBoolean([vr])[0])}
    got = port_access(ours, _ports(variables, outputs), False, False).read()
    want = [read[n](variables[n].valueReference) for n in outputs]
    assert [type(v) for v in got] == [type(v) for v in want]
    assert got == want


@_FIXTURES
@given(st.lists(st.tuples(st.lists(st.floats(-1e3, 1e3), min_size=2, max_size=2), st.floats(-1e3, 1e3),
                          st.floats(-1e3, 1e3, width=32)), min_size=1, max_size=5))
def test_fmi3_arrays_and_scalars_of_two_float_types_read_and_write_as_fmpys_calls_do(statespace, steps):
    variables, ours, theirs = statespace
    inputs, outputs = ["u", "g", "k32"], ["y", "s", "pair", "s32"]
    writer = port_access(ours, _ports(variables, inputs, {"u": 2}), True, True)
    reader = port_access(ours, _ports(variables, outputs, {"y": 3, "pair": 2}), True, False)
    vr = {n: variables[n].valueReference for n in inputs + outputs}
    for u, g, k32 in steps:
        writer.write([u, g, k32])
        theirs.setFloat64([vr["u"]], u)
        theirs.setFloat64([vr["g"]], [g])
        theirs.setFloat32([vr["k32"]], [k32])
        for s in (ours, theirs):
            s.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.01)
        assert reader.read() == [theirs.getFloat64([vr["y"]], 3), theirs.getFloat64([vr["s"]])[0],
                                 theirs.getFloat64([vr["pair"]], 2), theirs.getFloat32([vr["s32"]])[0]]


def test_a_call_the_fmu_refuses_raises_naming_the_function_and_status(statespace):
    variables, ours, _ = statespace
    # y holds 3 elements at the default sizes: a read of 2 is refused by the FMU itself
    reader = port_access(ours, _ports(variables, ["y"], {"y": 2}), True, False)
    with pytest.raises(FMICallException, match=r"fmi3GetFloat64 failed with status 3 \(error\)"):
        reader.read()


def test_logged_calls_and_ports_without_a_fixed_size_go_through_fmpy(statespace, types_fmu):
    variables, ours, _ = statespace
    assert port_access(ours, _ports(variables, ["s", "greeting"]), True, False) is None
    assert port_access(ours, _ports(variables, ["s", "blob_out"]), True, False) is None
    variables2, ours2, _ = types_fmu
    ours2.fmiCallLogger = print
    try:
        assert port_access(ours2, _ports(variables2, ["ry"]), False, False) is None
    finally:
        ours2.fmiCallLogger = None
