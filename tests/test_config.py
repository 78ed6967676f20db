"""Project JSON validation: the shipped configs pass, and one bad file per rule fails clearly."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hycosim.core.schema import polls_before_blocking

from hycosim.core.config import ConfigError, gateway_address, load_project, parse_project, server_endpoint
from hycosim.core.endpoints import PROTOCOLS, Address, EndpointError, parse_address, parse_endpoint
from hycosim.transport.session import zenoh_message
from tests.helpers import REPO, hycosim, write_project

GOOD = {
    "projectName": "demo",
    "serverIP": "127.0.0.1:7447",
    "nodeNum": 3,
    "nodeLists": [
        {"nodeName": "a", "UID": 1, "model": "ramp", "input": [], "output": ["y", "v"]},
        {"nodeName": "b", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
        {"nodeName": "c", "UID": 3, "model": "gain", "input": ["u", {"name": "n", "type": "Integer"}],
         "output": [{"name": "y"}, {"name": "flag", "type": "Boolean"}]},
    ],
    "linkNum": 3,
    "linkLists": [
        {"from": "a.y", "to": "b.u"},
        {"from": "b.y", "to": "c.u", "activeIn": ["free"]},
        {"from": "a", "to": "c", "pairs": [["v", "u"]], "activeIn": ["hold"]},
    ],
    "events": [{"name": "hold", "when": "c.flag", "drives": "c", "until": "not c.flag and a.y > 1"}],
}


def _write(tmp_path: Path, doc: dict) -> Path:
    p = tmp_path / "project.json"
    p.write_text(json.dumps(doc))
    return p


def _bad(tmp_path: Path, mutate) -> ConfigError:
    doc = copy.deepcopy(GOOD)
    mutate(doc)
    with pytest.raises(ConfigError) as info:
        load_project(_write(tmp_path, doc))
    return info.value


def test_good_file_loads_with_routes_and_guards(tmp_path):
    loaded = load_project(_write(tmp_path, GOOD))
    assert [(r.src_node, r.src_port, r.dst_node, r.dst_port) for r in loaded.routes] == [
        ("a", "y", "b", "u"), ("b", "y", "c", "u"), ("a", "v", "c", "u")]
    assert loaded.routes[1].active("free") and not loaded.routes[1].active("hold")
    assert loaded.routes[0].active("hold")
    guards = loaded.guards["hold"]
    assert guards.when.references == [("c", "flag")] and guards.rearm is None
    assert len(loaded.digest) == 64


def test_a_guard_naming_a_node_with_a_dash_says_that_is_why_it_does_not_parse(tmp_path):
    def dashed(doc):
        doc["nodeLists"][2]["nodeName"] = "c-1"  # a name the config's pattern allows
        doc["linkLists"][1]["to"], doc["linkLists"][2]["to"] = "c-1.u", "c-1"
        doc["events"][0].update({"drives": "c-1", "when": "c-1.flag", "until": "a.y > 1"})

    rendered = [i.render() for i in _bad(tmp_path, dashed).issues]
    assert rendered == ["events[0].when: guard 'c-1.flag' does not parse: invalid decimal literal (hint: a guard "
                        "cannot name node 'c-1': '-' is a minus there; give the node a name without '-')"]


@pytest.mark.parametrize("path", sorted((REPO / "hycosim").glob("**/configs/*.json")), ids=lambda p: p.name)
def test_shipped_configs_validate(path):
    # grasp-fmu.json and grasp-paper.json name FMUs that `hycosim scene fmus` builds (into
    # build/fmus, which a fresh clone lacks); test_grasp_scenario checks their models once built.
    fmus = any("fmu" in n for n in json.loads(path.read_text())["nodeLists"])
    res = hycosim("validate", str(path), *(["--no-models"] if fmus else []))
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith("OK")


def test_validate_checks_that_every_node_can_be_loaded_as_written(tmp_path):
    nodes = [
        {"nodeName": "g", "UID": 1, "model": "gain", "parameters": {"kk": 2.0}, "input": ["u"], "output": ["y"]},
        # a grasp node with a misspelt parameter used to run silently on the default angle
        {"nodeName": "rod", "UID": 2, "model": "rod", "parameters": {"initial_angle": 50}, "output": ["angle"]},
        {"nodeName": "x", "UID": 3, "model": "no_such_module:Thing", "output": ["y"]},
        {"nodeName": "src", "UID": 4, "model": "gain", "async": True, "output": ["y"]},
        {"nodeName": "f", "UID": 5, "fmu": "missing.fmu", "output": ["y"]},
        {"nodeName": "fine", "UID": 6, "model": "ramp", "parameters": {"a": 1.0}, "output": ["y", "v"]},
        # an input read with a default: misspelt, the camera's correction would never reach the twin
        {"nodeName": "twin", "UID": 7, "model": "rod", "input": ["meas_angel"], "output": ["angle", "omega"]},
        {"nodeName": "h", "UID": 8, "model": "gain", "input": ["u"], "output": ["y", "y2"]},
    ]
    p = write_project(tmp_path / "p.json", nodes, [{"from": "fine.y", "to": "g.u"}])
    res = hycosim("validate", str(p))
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert f"{p}: 7 node(s) cannot be loaded" in res.stderr
    lines = [line.strip() for line in res.stderr.splitlines()[1:]]
    assert len(lines) == 7 and all(line.startswith(f"{p}: nodeLists[") for line in lines)
    assert "nodeLists[0]: node 'g': model 'gain' has no parameter 'kk'" in lines[0] and "did you mean 'k'?" in lines[0]
    assert "nodeLists[1]: node 'rod'" in lines[1] and "did you mean 'initial_angle_deg'?" in lines[1]
    assert "nodeLists[2]: node 'x': cannot load model 'no_such_module:Thing'" in lines[2]
    assert "nodeLists[3]: node 'src' is asynchronous but hycosim.node.reference.gain:Gain is not an AsyncSource" in lines[3]
    assert "nodeLists[4]: node 'f': FMU file" in lines[4] and "missing.fmu does not exist" in lines[4]
    assert "nodeLists[6]: node 'twin': model 'rod' has no input 'meas_angel'" in lines[5]
    assert "did you mean 'meas_angle'?" in lines[5]
    assert "nodeLists[7]: node 'h': model 'gain' has no output 'y2' (its outputs: y)" in lines[6]
    res = hycosim("validate", str(p), "--no-models")
    assert res.returncode == 0 and res.stdout.rstrip().endswith("(models not checked)")


def test_a_model_module_that_fails_to_import_is_named_not_raised(tmp_path, monkeypatch):
    from hycosim.node.loader import NodeLoadError, check_node

    (tmp_path / "half_written.py").write_text("class Thing(:\n")
    (tmp_path / "raising.py").write_text("raise RuntimeError('needs a licence server')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    doc = copy.deepcopy(GOOD)
    for module, expected in (("half_written", "SyntaxError"), ("raising", "RuntimeError: needs a licence server")):
        doc["nodeLists"][0]["model"] = f"{module}:Thing"
        spec = parse_project(doc).project.nodeLists[0]
        with pytest.raises(NodeLoadError, match=f"node 'a': cannot load model '{module}:Thing': {expected}"):
            check_node(spec, tmp_path)


CASES = {
    "unknown key": (lambda d: d["nodeLists"][0].update(outputs=["x"]), "nodeLists[0].outputs", "unknown key"),
    "nodeNum disagrees": (lambda d: d.update(nodeNum=4), "nodeNum", "nodeNum is 4"),
    "linkNum disagrees": (lambda d: d.update(linkNum=1), "linkNum", "linkNum is 1"),
    "duplicate name": (lambda d: d["nodeLists"][1].update(nodeName="a"), "nodeLists[1].nodeName", "duplicate node name"),
    # A run's folder holds files named after each node; a file name has at most 255 bytes.
    "node name too long for a file name": (lambda d: d["nodeLists"][0].update(nodeName="a" * 201),
                                           "nodeLists[0].nodeName", "at most 200 characters"),
    "duplicate UID": (lambda d: d["nodeLists"][2].update(UID=1), "nodeLists[2].UID", "duplicate UID 1"),
    "link from an input": (lambda d: d["linkLists"][0].update({"from": "b.u"}), "linkLists[0]", "not an output of node 'b'"),
    "link to an output": (lambda d: d["linkLists"][0].update({"to": "b.y"}), "linkLists[0]", "not an input of node 'b'"),
    "link to unknown node": (lambda d: d["linkLists"][0].update({"to": "zz.u"}), "linkLists[0].to", "unknown node 'zz'"),
    "two feeders in one mode": (lambda d: d["linkLists"][2].update(activeIn=["free"]), "linkLists[2].to",
                                "also fed by linkLists[1] in mode 'free'"),
    "type mismatch": (lambda d: d["linkLists"].append({"from": "a.y", "to": "c.n"}) or d.update(linkNum=4),
                      "linkLists[3]", "type mismatch: a.y is Real, c.n is Integer"),
    "guard does not parse": (lambda d: d["events"][0].update(when="c.flag >"), "events[0].when", "does not parse"),
    "guard names unknown port": (lambda d: d["events"][0].update(until="c.nothing > 1"), "events[0].until",
                                 "c.nothing, which is not a node output"),
    "rearm guard names unknown port": (lambda d: d["events"][0].update(rearm="c.flagg"), "events[0].rearm",
                                       "c.flagg, which is not a node output"),
    "drivenVariable on a Python node": (lambda d: d["nodeLists"][0].update(drivenVariable="follow"),
                                        "nodeLists[0].drivenVariable", "is not an FMU node"),
    "guard calls code": (lambda d: d["events"][0].update(when="__import__('os').system('true')"), "events[0].when",
                         "not allowed"),
    "unknown mode": (lambda d: d["linkLists"][1].update(activeIn=["grab"]), "linkLists[1].activeIn", "unknown mode 'grab'"),
    "event drives unknown node": (lambda d: d["events"][0].update(drives="ghost"), "events[0].drives", "unknown node"),
    "unknown wait strategy": (lambda d: d.update(coSimulation={"waitStrategy": "spin"}),
                              "coSimulation.waitStrategy", "Input should be 'auto', 'block' or 'yield'"),
    "server port not a number": (lambda d: d.update(serverIP="127.0.0.1:74a7"), "serverIP", "port '74a7' is not a number"),
    "server port out of range": (lambda d: d.update(serverIP="10.0.0.5:70000"), "serverIP", "outside 1-65535"),
    "server protocol": (lambda d: d.update(serverIP="udp/10.0.0.5:7447"), "serverIP", "not udp/"),
    "gateway port out of range": (lambda d: d.update(gatewayIP="127.0.0.1:0"), "gatewayIP", "port 0 is outside"),
    "gateway beside the last port": (lambda d: d.update(serverIP="127.0.0.1:65535"), "gatewayIP", "is the last port"),
    "step below the clock's resolution": (lambda d: d.update(coSimulation={"stepSize": 1e-20, "startTime": 1.0,
                                                                           "stopTime": 2.0}),
                                          "coSimulation.stepSize", "does not advance a time of 1 s (startTime)"),
    "endless stop time": (lambda d: d.update(coSimulation={"stopTime": float("inf")}), "coSimulation.stopTime",
                          "Input should be a finite number"),
    "negative real-time factor": (lambda d: d.update(coSimulation={"realTime": -2}), "coSimulation.realTime",
                                  "realTime -2 is negative"),
    "event tolerance no finer than a step": (lambda d: d.update(coSimulation={"stepSize": 0.01, "eventTolerance": 0.01}),
                                             "coSimulation.eventTolerance", "not smaller than stepSize 0.01 s"),
    "bad port type": (lambda d: d["nodeLists"][1].update(input=[{"name": "u", "type": "Float"}]),
                      "nodeLists[1].input[0].type", "Input should be"),
    # Zenoh took it in whole milliseconds as a 64-bit integer: a Json5Err of 300 digits in each node.
    "a wait of ages": (lambda d: d.update(coSimulation={"attachTimeout": 1e300}), "coSimulation.attachTimeout",
                       "less than or equal to 1000000"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_each_rule_rejects_with_path_and_hint(tmp_path, case):
    mutate, path, text = CASES[case]
    err = _bad(tmp_path, mutate)
    rendered = [i.render() for i in err.issues]
    assert any(r.startswith(path) and text in r for r in rendered), rendered
    assert str(tmp_path / "project.json") in str(err)


def test_all_errors_reported_at_once(tmp_path):
    err = _bad(tmp_path, lambda d: (d.update(nodeNum=9, linkNum=9), d["nodeLists"][2].update(UID=2)))
    paths = {i.path for i in err.issues}
    assert {"nodeNum", "linkNum", "nodeLists[2].UID"} <= paths


def test_duplicate_json_key_and_bad_json(tmp_path):
    p = tmp_path / "dup.json"
    p.write_text('{"nodeNum": 1, "nodeNum": 2, "nodeLists": []}')
    with pytest.raises(ConfigError, match="duplicate key 'nodeNum'"):
        load_project(p)
    p.write_text('{"nodeNum": 1,, }')
    with pytest.raises(ConfigError, match="line 1 column"):
        load_project(p)
    with pytest.raises(ConfigError, match="cannot read"):
        load_project(tmp_path / "missing.json")


def test_file_that_is_not_json_text_is_named_not_a_traceback(tmp_path):
    p = tmp_path / "deep.json"
    p.write_text("[" * 100_000 + "]" * 100_000)  # the decoder recurses once per level
    with pytest.raises(ConfigError, match="nested too deeply"):
        load_project(p)
    p.write_bytes(b'{"projectName": "\xff"}')
    with pytest.raises(ConfigError, match="byte 17 cannot be read as utf-8") as caught:
        load_project(p)
    assert "once per object" not in str(caught.value)  # not the duplicate-key hint
    res = hycosim("validate", str(p))
    assert res.returncode == 2 and "Traceback" not in res.stderr and "save the project file as UTF-8" in res.stderr


def test_cli_lists_every_error_and_exits_2(tmp_path):
    doc = copy.deepcopy(GOOD)
    doc["nodeNum"] = 7
    doc["linkLists"][0]["to"] = "b.nope"
    p = _write(tmp_path, doc)
    res = hycosim("validate", str(p))
    assert res.returncode == 2
    assert f"{p}: nodeNum: nodeNum is 7" in res.stderr
    assert "linkLists[0].to: b.nope is not an input of node 'b'" in res.stderr
    assert "hint:" in res.stderr
    assert "Traceback" not in res.stderr


def test_server_ip_forms():
    assert server_endpoint("10.0.0.5") == "tcp/10.0.0.5:7447"
    assert server_endpoint("10.0.0.5:9000") == "tcp/10.0.0.5:9000"
    assert server_endpoint("tcp/127.0.0.1:7448") == "tcp/127.0.0.1:7448"
    assert server_endpoint("server") == "tcp/server:7447"  # a compose service name
    assert server_endpoint("[::1]:9000") == "tcp/[::1]:9000"
    assert server_endpoint("::1") == "tcp/[::1]:7447"
    assert server_endpoint("tls/robot-cell.lan:7447") == "tls/robot-cell.lan:7447"
    assert server_endpoint("tcp/10.0.0.5:7447#iface=eth0") == "tcp/10.0.0.5:7447#iface=eth0"


@pytest.mark.parametrize("text, reason", [
    ("/work/configs/grasp.json", "(a path?)"),
    ("udp/10.0.0.5:7447", "not udp/"),
    ("10.0.0.5:", "port '' is not a number"),
    ("10.0.0.5:0", "port 0 is outside 1-65535"),
    ("tcp/", "names no host"),
    ("my host", "'my host' is not a host name"),
    ("[::1:7447", "written [ADDRESS]:PORT"),
])
def test_unusable_endpoints_are_named_with_the_reason(text, reason):
    with pytest.raises(EndpointError) as exc:
        parse_endpoint(text)
    assert repr(text) in str(exc.value) and reason in str(exc.value)


# Addresses as people write them, right or with one part wrong: hosts, IPv4 and IPv6, ports
# in and out of range or not ASCII digits ("²".isdigit() holds), stray whitespace, suffixes.
_hosts = (st.from_regex(r"[a-z][a-z0-9\-]{0,12}[a-z0-9](\.[a-z]{2,5}){0,2}", fullmatch=True)
          | st.sampled_from(["127.0.0.1", "10.0.0.5", "localhost", "compose_server", "host."])
          | st.sampled_from(["[::1]", "[fe80::1%eth0]", "::1", "[::1", "::1]"])
          | st.text(max_size=8))
_ports = (st.none() | st.integers(0, 70000).map(str) | st.sampled_from(["", "²", "٧٤٤٧", "7447 ", "+80", "0x50", "9" * 5000])
          | st.text(max_size=4))
_endings = st.sampled_from(["", "", "\n", " ", "\t\n"])


@st.composite
def _written_addresses(draw) -> str:
    protocol = draw(st.sampled_from(["", "", "tcp/", "tls/", "udp/", "TCP/", "tcp//"]))
    port = draw(_ports)
    suffix = draw(st.sampled_from(["", "", "?prio=1", "#iface=eth0"]) | st.text(max_size=4))
    text = protocol + draw(_hosts) + draw(_endings) + ("" if port is None else ":" + port) + suffix
    return draw(st.sampled_from(["", " "])) + text + draw(_endings)


@given(_written_addresses())
def test_any_endpoint_a_user_writes_is_read_or_named_with_what_is_wrong(text):
    """An endpoint read is one Zenoh can take (TCP or TLS, an ASCII host with no space, a port
    in range) and reads back the same; any other is refused as EndpointError quoting it. Before,
    a port of "²" raised int()'s ValueError, "٧٤٤٧" was taken as 7447, and a host ending in a
    newline passed ("$" matches before one)."""
    try:
        endpoint = parse_endpoint(text)
    except EndpointError as exc:
        assert repr(text) in str(exc)
    else:
        host = endpoint.address.host
        assert endpoint.protocol in PROTOCOLS and 1 <= endpoint.address.port <= 65535
        assert host.isascii() and host.isprintable() and not any(c.isspace() for c in host)
        assert parse_endpoint(str(endpoint)) == endpoint
    try:
        address = parse_address(text, 7448)
    except EndpointError as exc:
        assert repr(text) in str(exc)
    else:
        assert address.host.isascii() and not any(c.isspace() for c in address.host)
        assert 1 <= address.port <= 65535 and parse_address(str(address), 7448) == address


def test_gateway_address_defaults_beside_the_server():
    doc = copy.deepcopy(GOOD)
    project = parse_project(doc).project
    assert gateway_address(project) == Address("127.0.0.1", 7448)
    assert gateway_address(project, "tcp/0.0.0.0:9000") == Address("0.0.0.0", 9001)
    doc["gatewayIP"] = "tcp/[::1]:9100"
    assert str(gateway_address(parse_project(doc).project)) == "[::1]:9100"
    with pytest.raises(EndpointError, match="'tls/h:1' is not a HOST:PORT address"):
        parse_address("tls/h:1", 7448)


@pytest.mark.parametrize("args, option", [
    (["node", "a", "{cfg}", "--connect", "udp/127.0.0.1:7447"], "--connect"),
    (["server", "{cfg}", "--runs-dir", "{tmp}/runs", "--listen", "127.0.0.1:port"], "--listen"),
    (["server", "{cfg}", "--runs-dir", "{tmp}/runs", "--gateway", "127.0.0.1:123456"], "--gateway"),
    (["run", "{cfg}", "--runs-dir", "{tmp}/runs", "--listen", "unixsock-stream//tmp/hy.sock"], "--listen"),
    (["status", "{cfg}"], "endpoint"),  # the config file given where the endpoint goes
    (["fmu", "build", "{cfg}", "--server", "tls/127.0.0.1:7448", "-o", "{tmp}/fmus"], "--server"),
])
def test_cli_names_an_unusable_address_and_writes_nothing(tmp_path, args, option):
    cfg = _write(tmp_path, GOOD)
    res = hycosim(*(a.format(cfg=cfg, tmp=tmp_path) for a in args))
    assert res.returncode == 2, res.stderr
    assert f"error: {option}: " in res.stderr
    assert "Traceback" not in res.stderr and ".rs:" not in res.stderr
    assert not (tmp_path / "runs").exists() and not (tmp_path / "fmus").exists()


def test_zenoh_errors_lose_their_rust_source_locations():
    exc = RuntimeError("Unable to connect to any of [Single(tcp/127.0.0.1:1)]. Timeout! at "
                       "/root/.cargo/git/checkouts/zenoh-9c599d5ef3e0480e/cc83980/zenoh/src/net/runtime/orchestrator.rs:388.")
    assert zenoh_message(exc) == "Unable to connect to any of [Single(tcp/127.0.0.1:1)]. Timeout!"


def test_wait_strategy_polls_only_where_the_processes_fit_the_cores(tmp_path):
    # auto: up to two processes (the server and the nodes) per core.
    assert polls_before_blocking("auto", 4, 2) is True
    assert polls_before_blocking("auto", 5, 2) is False
    assert polls_before_blocking("auto", 32, 16) is True and polls_before_blocking("auto", 33, 16) is False
    assert polls_before_blocking("auto", 2, None) is True and polls_before_blocking("auto", 3, None) is False
    assert polls_before_blocking("yield", 17, 2) is True
    assert polls_before_blocking("block", 2, 64) is False
    doc = copy.deepcopy(GOOD)  # 3 nodes and the server: 4 processes
    doc["coSimulation"] = {"waitStrategy": "auto"}
    project = load_project(_write(tmp_path, doc)).project
    assert project.polls_before_blocking(1) is False and project.polls_before_blocking(2) is True


# Project files as a hand leaves them: a project this suite or the repository ships, with up
# to three edits anywhere in its tree (a value replaced by one of another kind or range, a key
# deleted or added, a list entry repeated), none at all a third of the time.
_BASES = [GOOD, *(json.loads(p.read_text()) for p in sorted((REPO / "hycosim").glob("**/configs/*.json")))]
_JUNK = st.sampled_from([None, -1, 0, 1, 2.5, -0.0, 1e308, float("nan"), float("inf"), "", "x", "a.y", "free", "é²",
                         "0", [], {}, [1], {"a": 1}, True, False, "x" * 300, 2 ** 70, "..", "/etc/passwd",
                         "a.y >= 0.3", "__import__('os')", "1 +", "a.b.c", "tcp/127.0.0.1:²", "hold"]
                        ).map(copy.deepcopy)  # a fresh [] or {} each draw: a later edit may add to it
_KEYS = st.sampled_from(["extra", "async", "stepSize", "fmu", "model", "activeIn", "rate", "pairs", "order",
                         "coupling", "events", "gatewayIP", "checkpointEvery", "replay", "until"])


def _paths(value, at=()):
    yield at
    children = value.items() if type(value) is dict else enumerate(value) if type(value) is list else ()
    for key, child in children:
        yield from _paths(child, (*at, key))


@st.composite
def _edited_projects(draw) -> dict:
    doc = copy.deepcopy(draw(st.sampled_from(_BASES)))
    for _ in range(draw(st.sampled_from([0, 1, 1, 2, 3]))):
        path = draw(st.sampled_from([p for p in _paths(doc) if p]))
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        how = draw(st.sampled_from(["replace", "replace", "delete", "add", "repeat"]))
        if how == "delete" and type(parent) is dict:
            del parent[path[-1]]
        elif how == "add" and type(parent) is dict:
            parent[draw(_KEYS)] = draw(_JUNK)
        elif how == "repeat" and type(parent) is list:
            parent.append(copy.deepcopy(parent[path[-1]]))
        else:
            parent[path[-1]] = draw(_JUNK | st.sampled_from([copy.deepcopy(parent[path[-1]])]))
    return doc


@given(_edited_projects())
def test_any_edited_project_file_is_a_project_the_run_can_use_or_named_errors(tmp_path_factory, doc):
    """What the loader accepts, the server and nodes can use as it is: the counts match, names
    and UIDs are unique, every route joins an output to an input of nodes that exist in modes
    that exist, every event drives a node and has compiled guards, times are finite and in
    order, the addresses parse and the coupling plans. What it refuses is a ConfigError naming
    the file and, for each problem, where in it."""
    path = tmp_path_factory.mktemp("edited") / "project.json"
    path.write_text(json.dumps(doc))
    try:
        loaded = load_project(path)
    except ConfigError as exc:
        assert str(path) in str(exc) and exc.issues and all(i.path and i.message for i in exc.issues)
        return
    p, cosim = loaded.project, loaded.project.coSimulation
    assert p.nodeNum == len(p.nodeLists) and p.linkNum == len(p.linkLists)
    nodes = {n.nodeName: n for n in p.nodeLists}
    assert len(nodes) == len(p.nodeLists) and len({n.UID for n in p.nodeLists}) == len(p.nodeLists)
    for r in loaded.routes:
        assert r.src_port in nodes[r.src_node].output_names() and r.dst_port in nodes[r.dst_node].input_names()
        assert r.active_in is None or r.active_in <= set(p.modes())
    for e in p.events:
        assert e.drives in nodes and e.name in loaded.guards
    assert math.isfinite(cosim.startTime) and math.isfinite(cosim.stopTime) and cosim.startTime < cosim.stopTime
    server_endpoint(p.serverIP)
    gateway_address(p)
    assert set(loaded.coupling.rates) >= {n.nodeName for n in p.nodeLists if not n.asynchronous}
