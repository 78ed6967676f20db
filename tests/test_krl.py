"""EthernetKRL: exported files checked against the format, the frame stream through the emulated
controller over TCP, each malformed input, and a short trials run producing the table and files."""

from __future__ import annotations

import csv
import json
import math
import re
import time
import socket
import threading
import xml.etree.ElementTree as ET
from xml.sax.saxutils import escape

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hycosim.scenario.krl.controller import MAX_FRAME_BYTES, EmulatedController, Program, parse_ack, stream_program
from hycosim.scenario.krl.eki import AXES, EkiConfig, EkiError, frame, parse_frame
from hycosim.scenario.krl.export import ExportError, export, read_path
from hycosim.scenario.robot import kr6
from hycosim.scenario.robot.scene import SceneParams
from hycosim.scenario.rod.model import RodParams
from tests.helpers import REPO, hycosim, run_project

TWIN = RodParams(length=0.6, mass=0.3, damping=0.002, pivot=(0.62, 0.0, 1.0), grasp_distance=0.4,
                 initial_angle=math.radians(40))


@pytest.fixture(scope="module")
def grasp_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("krl")
    doc = json.loads((REPO / "hycosim" / "scenario" / "configs" / "grasp.json").read_text())
    doc["coSimulation"]["stopTime"] = 1.2
    cfg = tmp / "grasp.json"
    cfg.write_text(json.dumps(doc))
    run = run_project(cfg, tmp / "runs")
    return run, export(run, tmp / "krl")


@pytest.fixture
def controller():
    c = EmulatedController(EkiConfig(), TWIN, port=0)
    t = threading.Thread(target=c.serve_forever, daemon=True)
    t.start()
    yield c
    c.stop()
    t.join(timeout=5)


def test_eki_file_and_krl_program_follow_the_format(grasp_run):
    _, files = grasp_run
    root = ET.parse(files["eki"]).getroot()
    assert root.tag == "ETHERNETKRL"
    assert root.findtext("CONFIGURATION/EXTERNAL/TYPE") == "Client"
    assert root.findtext("CONFIGURATION/EXTERNAL/PORT") == root.findtext("CONFIGURATION/INTERNAL/PORT") == "54600"
    assert root.find("CONFIGURATION/INTERNAL/BUFFERING") is not None
    tags = {e.get("Tag"): e.get("Type") for e in root.findall("RECEIVE/XML/ELEMENT")}
    assert all(tags[f"Robot/Pos/@{a}"] == "REAL" for a in AXES)
    assert EkiConfig.parse(files["eki"].read_text(), str(files["eki"])).port == 54600
    krl = files["krl"].read_text()
    for piece in ("DEF HycosimGrasp()", "DECL E6AXIS XP1", "PTP XP1", 'EKI_Init("HycosimGrasp")',
                  'EKI_Open("HycosimGrasp")', "LOOP", "IF RET.Buff == 0 THEN", "EXIT", "ENDLOOP",
                  'EKI_Close("HycosimGrasp")', "END"):
        assert piece in krl, piece
    assert all(f"XP1.{a}" in krl for a in AXES[1:])
    assert krl.index("PTP XP1") < krl.index("EKI_Open") < krl.index("LOOP")  # reset, open, loop (Table 1)
    lines = files["frames"].read_text().splitlines()
    config = EkiConfig()
    parsed = [parse_frame(line, config) for line in lines]
    assert parsed[-1].q_deg is None and all(p.q_deg is not None for p in parsed[:-1])
    assert [p.t for p in parsed[:-1]] == sorted(p.t for p in parsed[:-1])
    assert any(p.close for p in parsed[:-1])


def test_frame_stream_round_trip_through_the_controller(grasp_run, controller):
    run, files = grasp_run
    answer = parse_ack(stream_program("127.0.0.1", controller.address[1], files["frames"].read_text()))
    n = len(files["frames"].read_text().splitlines()) - 1
    assert answer["frames"] == n and answer["rejected"] == 0
    # The controller's rod is the twin itself here: the exported path grasps it as the
    # simulation did, at the same step and as far from the grasp point.
    with open(run / "values.csv", newline="") as f:
        grasp = next(r for r in csv.DictReader(f) if float(r["robot.grasped"]) > 0.5)
    offset = math.dist([float(grasp[f"robot.tcp_{c}"]) for c in "xyz"], [float(grasp[f"rod.grasp_{c}"]) for c in "xyz"])
    assert answer["grasped"] and answer["grasp_time_s"] == pytest.approx(float(grasp["t"]), abs=1e-6)
    assert answer["grasp_error_mm"] == pytest.approx(1000 * offset, abs=0.01)
    assert len(controller.results) == 1


def test_the_controller_is_where_the_twin_was_at_every_step(grasp_run):
    run, files = grasp_run
    recorded = read_path(run)
    program = Program(TWIN, SceneParams())
    frames = [parse_frame(line, EkiConfig()) for line in files["frames"].read_text().splitlines()[:-1]]
    worst = 0.0
    for k, f in enumerate(frames[1:]):
        program.run_until(f.t)
        assert f.t == pytest.approx(recorded.t[k])
        worst = max(worst, max(abs(a - b) for a, b in zip(np.degrees(program.scene.q), recorded.q_deg[k])))
        program.accept(f.q_deg, f.t, f.close)
    program.run_until(recorded.t[-1])
    last = max(abs(a - b) for a, b in zip(np.degrees(program.scene.q), recorded.q_deg[-1]))
    # Each frame's move, started at its T, ends where the twin's robot was a step later; a
    # frame holding the point of its own time would leave the robot a whole step behind.
    # (Frames carry 4 decimals of a degree.)
    assert max(worst, last) < 1e-4 and len(frames) == len(recorded.t)
    assert program.result.grasped and program.result.grasp_time_s == pytest.approx(recorded.t[-1])


def test_the_gripper_follows_every_frame_so_a_path_may_reopen_after_closing_on_nothing(grasp_run, controller):
    _, files = grasp_run
    config = EkiConfig()
    lines = files["frames"].read_text().splitlines()
    parsed = [parse_frame(line, config) for line in lines[:-1]]
    assert next(i for i, p in enumerate(parsed) if p.close) > 30
    # The jaws close on nothing for the first 0.15 s, open again, and close on the rod as exported.
    edited = [frame(p.q_deg, p.t, i < 15 or p.close) for i, p in enumerate(parsed)]
    ack = parse_ack(stream_program("127.0.0.1", controller.address[1], "\n".join([*edited, lines[-1]]) + "\n"))
    assert ack["grasped"] and ack["grasp_error_mm"] < 5.0
    assert "$OUT[1] = CLOSE" in files["krl"].read_text()


def test_malformed_inputs_are_rejected_and_the_controller_keeps_running(grasp_run, controller):
    _, files = grasp_run
    host, port = "127.0.0.1", controller.address[1]
    good = files["frames"].read_text().splitlines()
    bad = [
        "<Robot><Pos A1='1' <broken></Robot>",                                   # malformed XML
        frame([200.0, -90, 90, 0, 0, 0], 0.0),                                    # A1 beyond ±170°
        good[0].replace('A3="', 'A3="x'),                                         # not a REAL
        "<Other/></Robot>",                                                       # not a Robot frame
        frame([0.0, -90, 90, 0, 0, 0], 1e300),                                    # a wait without end
        frame([0.0, -90, 90, 0, 0, 0], math.nan),                                 # no time at all
    ]
    answer = stream_program(host, port, "\n".join([*bad, *good]) + "\n", timeout=30)
    assert "outside its limits" in answer and "malformed XML" in answer and "is not REAL" in answer
    assert "T=1e+300 s is outside a program's time [0, 120] s" in answer and "T=nan s is outside" in answer
    ack = parse_ack(answer)
    assert ack["rejected"] == 6 and ack["grasped"]
    # A peer that never ends a frame is cut off at a bound, not buffered for ever.
    with socket.create_connection((host, port), timeout=30) as s:
        s.sendall(b"<Robot>" + b" " * MAX_FRAME_BYTES)  # all of it read before the cut: no reset
        reply = ET.fromstring(s.recv(4096))  # XML the PC reads, the frame end in it quoted
        assert reply.find("Error").get("Msg").startswith("no frame end (</Robot>) in ")
    # A connection that drops mid-program is rejected too; the next program still runs.
    with socket.create_connection((host, port)) as s:
        s.sendall("\n".join(good[:5]).encode())
    for _ in range(100):
        if any("dropped" in e for e in controller.errors):
            break
        threading.Event().wait(0.05)
    assert any("dropped before the program ended (5 frames executed)" in e for e in controller.errors)
    assert parse_ack(stream_program(host, port, "\n".join(good) + "\n"))["grasped"]
    with pytest.raises(EkiError, match="lacks REAL elements for A6"):
        EkiConfig.parse(EkiConfig(elements=[(f"Robot/Pos/@{a}", "REAL") for a in AXES[:5]]).to_xml())


def test_export_and_controller_cli_errors(tmp_path):
    with pytest.raises(ExportError, match="cannot read"):
        export(tmp_path, tmp_path / "out")
    res = hycosim("krl", "export", str(tmp_path))
    assert res.returncode == 2 and "values.csv" in res.stderr
    q = [f"robot.q{i}" for i in range(1, 7)]
    header = ",".join(["step", "t", "mode", *q, "robot.grasped"])
    (tmp_path / "values.csv").write_text("step,t,mode,rod.angle\n0,0.0,free,0.1\n")
    with pytest.raises(ExportError, match="no joint path .* recorded for node 'robot'"):
        export(tmp_path, tmp_path / "out")
    (tmp_path / "values.csv").write_text(f"{header}\n0,0.0,free,0,0,0,0,0,0,0\n1,0.01,free,0,0,up,0,0,0,1\n")
    with pytest.raises(ExportError, match="line 3, column robot.q3: 'up' is not a finite number"):
        export(tmp_path, tmp_path / "out")
    (tmp_path / "values.csv").write_text(f"{header}\n0,0.0,free,0,0,0,0,0,0,0\n1,0.01,free,0,0,0.5,0,0,0,1\n")
    path = read_path(tmp_path)
    assert path.grasp_index == 1 and path.t == [0.0, 0.01] and path.q_deg[1][2] == pytest.approx(28.6479, abs=1e-3)
    (tmp_path / "bad.xml").write_text("<NOT/>")
    res = hycosim("krl", "controller", "--eki", str(tmp_path / "bad.xml"))
    assert res.returncode == 2 and "expected <ETHERNETKRL>" in res.stderr
    # Each once a traceback: a flag that is no number, a file that is no UTF-8 text.
    (tmp_path / "flag.xml").write_text(EkiConfig().to_xml().replace('Set_Flag="1"', 'Set_Flag="one"'))
    (tmp_path / "latin.xml").write_bytes(EkiConfig().to_xml().replace("Client", "Cli\xe9nt").encode("latin-1"))
    for name, says in (("flag.xml", "has Set_Flag 'one', not a flag number (1-1024)"), ("latin.xml", "not XML")):
        res = hycosim("krl", "controller", "--eki", str(tmp_path / name))
        assert res.returncode == 2 and says in res.stderr and "Traceback" not in res.stderr, res.stderr


@pytest.mark.parametrize("args, message", [
    (["--angles", "95", "--trials", "1"], "95° outside (0°, 90°)"),
    (["--angles", "-5", "40"], "-5° outside (0°, 90°)"),  # and "-o" after it is still an option
    (["--angles", "30", "--trials", "0"], "'--trials'"),
    (["--angles", "thirty"], "give numbers in degrees"),
    (["--angles", "30", "--nodes", "modelica"], "--nodes is 'fmu' or 'python'"),
    (["--angles", "40", "50", "40.0"], "40° given twice"),
])
def test_trials_refuse_bad_angles_and_counts_before_running(tmp_path, args, message):
    res = hycosim("trials", *args, "-o", str(tmp_path / "out"))
    assert res.returncode == 2 and message in res.stderr, res.stderr
    assert "Traceback" not in res.stderr and not (tmp_path / "out").exists()


def test_short_trials_run_produces_the_table_and_files(tmp_path):
    out = tmp_path / "trials"
    res = hycosim("trials", "--angles", "30", "50", "--trials", "1", "-o", str(out), timeout=900)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "paper %" in res.stdout and "│ 50°" in res.stdout and "rod and robot as FMUs" in res.stdout
    with open(out / "trials.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 2 and {r["angle"] for r in rows} == {"30.0", "50.0"}
    assert {r["nodes"] for r in rows} == {"fmu"}  # the paper's design: the rod and robot scene as FMUs
    project = json.loads(next(out.glob("30deg-00/project.json")).read_text())
    assert [n["nodeName"] for n in project["nodeLists"] if "fmu" in n] == ["rod", "robot"]
    # The trials' twin is the paper scenario's: the camera corrects it at the same rate.
    paper = json.loads((REPO / "hycosim" / "scenario" / "configs" / "grasp-paper.json").read_text())
    gains = [doc["nodeLists"][0]["parameters"]["observer_gain"] for doc in (project, paper)]
    assert gains[0] == gains[1] > 0
    assert all(r["success"] == "True" for r in rows)  # the shipped policy grasps every trial at 30–50°
    assert (out / "trials.png").stat().st_size > 20_000
    one = next(out.glob("30deg-00/krl/frames.xml"))
    assert one.read_text().strip().splitlines()[-1].startswith('<Robot><Pos A1=""')


def test_a_trial_that_cannot_run_is_recorded_and_the_others_go_on(tmp_path):
    out = tmp_path / "trials"
    out.mkdir()
    (out / "30deg-00").write_text("a file where the first trial's folder goes")
    # With the Python nodes (--nodes python) rather than the FMUs: the table and the CSV say which ran.
    res = hycosim("trials", "--angles", "30", "--trials", "2", "--nodes", "python", "-o", str(out), timeout=300)
    assert res.returncode == 3 and "30° #0: not run" in res.stderr and "1 of 2 trials could not be run" in res.stderr
    assert "rod and robot as Python nodes" in res.stdout
    assert "Traceback" not in res.stderr
    with open(out / "trials.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["trial"] for r in rows] == ["0", "1"]
    assert rows[0]["success"] == "False" and "30deg-00" in rows[0]["error"]
    assert rows[1]["error"] == "" and rows[1]["success"] == "True"
    assert [r["nodes"] for r in rows] == ["python", "python"]
    project = json.loads(next(out.glob("30deg-01/project.json")).read_text())
    assert not any("fmu" in n for n in project["nodeLists"])
    assert "50 % of 2" in res.stdout


@pytest.mark.long
def test_the_papers_eighty_trials(tmp_path):
    from hycosim.scenario.trials import run_trials, summarise

    table = summarise(run_trials([30, 40, 50, 60], 20, tmp_path / "trials"))
    assert all(row["success_pct"] >= 95 for row in table.values())
    assert all(row["error_mm"] <= 3.0 for row in table.values())
    assert all(row["time_s"] <= 5.0 for row in table.values())


def test_ctrl_c_stops_the_trials_and_tabulates_the_finished_ones(tmp_path):
    """A terminal's Ctrl-C (the whole process group) during the second trial: no further trial
    starts, the first is in the table and CSV, and the exit status says interrupted."""
    import os
    import signal

    from tests.helpers import reap, spawn, wait_for

    out = tmp_path / "trials"
    csv_rows = lambda: len((out / "trials.csv").read_text().splitlines()) - 1 if (out / "trials.csv").exists() else 0  # noqa: E731
    proc = spawn("trials", "--angles", "40", "--trials", "3", "--driver", "reference", "-o", str(out),
                 start_new_session=True)
    try:
        wait_for(lambda: csv_rows() >= 1, 90, "the first trial")
        wait_for(lambda: (out / "40deg-01" / "runs").exists(), 30, "the second trial to start")
        time.sleep(1.0)
        os.killpg(proc.pid, signal.SIGINT)
        stdout, err = proc.communicate(timeout=60)
        assert proc.returncode == 130, err
        assert "interrupted by Ctrl-C after 1 trial of 3: the table holds those" in err and "Traceback" not in err
        assert "of 1" in stdout and csv_rows() == 1 and not (out / "40deg-02").exists()
        assert (out / "trials.png").stat().st_size > 10_000
    finally:
        reap(proc)


def _trial_rows(out) -> list[dict]:
    with open(out / "trials.csv", newline="") as f:
        return [{k: v for k, v in row.items() if k != "run_dir"} for row in csv.DictReader(f)]


def test_trials_on_dask_workers_equal_the_serial_ones_in_the_trials_order(tmp_path):
    """Without the camera a trial is deterministic: each run on a worker of a local cluster gives
    the row the same trial gives run alone; the table keeps the trials' order whichever ends
    first, and the workers' logs go to the trials' log, not to the terminal."""
    quick = ("--no-correction", "--driver", "reference", "--nodes", "python")
    res = hycosim("trials", "--angles", "30", "40", "--trials", "1", *quick, "--workers", "2",
                  "-o", str(tmp_path / "dask"), timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "│ 40°" in res.stdout and "program ended" not in res.stderr
    assert "program ended" in (tmp_path / "dask" / "trials.log.jsonl").read_text()
    alone = hycosim("trials", "--angles", "40", "--trials", "1", *quick, "-o", str(tmp_path / "alone"), timeout=300)
    assert alone.returncode == 0, alone.stderr[-2000:]
    rows = _trial_rows(tmp_path / "dask")
    assert [(r["angle"], r["trial"]) for r in rows] == [("30.0", "0"), ("40.0", "0")]
    assert rows[1] == _trial_rows(tmp_path / "alone")[0] and rows[1]["success"] == "True"
    both = hycosim("trials", "--angles", "40", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1",
                   "-o", str(tmp_path / "no"))
    assert both.returncode == 2 and "not both" in both.stderr


def test_ctrl_c_stops_the_trials_running_on_the_workers(tmp_path):
    """A terminal's Ctrl-C (the whole process group) during trials on two workers: the trials
    running there are stopped as a serial one is (their servers record an interrupted run), no
    further trial starts, the finished ones are in the table, and no worker prints a traceback
    (the workers leave the terminal's group: the trials' command alone answers Ctrl-C)."""
    import os
    import signal

    from tests.helpers import reap, spawn, wait_for

    out = tmp_path / "trials"
    proc = spawn("trials", "--angles", "40", "--trials", "6", "--driver", "reference", "--nodes", "python",
                 "--workers", "2", "-o", str(out), start_new_session=True)
    try:
        wait_for(lambda: (out / "trials.csv").exists(), 120, "the first trial")
        # A trial past the first two whose co-simulation is under way (its server's records open).
        wait_for(lambda: any('"status": "running"' in m.read_text()
                             for m in out.glob("40deg-0[2-5]/runs/*/meta.json")), 60, "a later trial to run")
        time.sleep(0.5)
        os.killpg(proc.pid, signal.SIGINT)
        stdout, err = proc.communicate(timeout=60)
        assert proc.returncode == 130, err
        assert "interrupted by Ctrl-C after" in err and "Traceback" not in err
        finished = _trial_rows(out)
        assert 1 <= len(finished) < 6 and all(r["error"] == "" for r in finished)
        statuses = {}
        for meta in out.glob("40deg-*/runs/*/meta.json"):
            wait_for(lambda: '"status": "running"' not in meta.read_text(), 30, f"{meta} to be closed")
            statuses[meta.parts[-4]] = json.loads(meta.read_text())["status"]
        assert "interrupted" in statuses.values(), statuses
    finally:
        reap(proc)


# Frame streams as a PC sends them, each frame right or with one thing wrong, the whole
# stream ended by the empty-A1 frame or by the connection closing.
_FRAME_WRONGS = ["axis", "time", "element", "root", "xml", "bytes", "entity", "markup"]


@st.composite
def _frame_streams(draw) -> tuple[bytes, int, int, bool]:
    """A stream, the number of its frames the controller executes and rejects, and whether it ends."""
    parts, executed, rejected = [], 0, 0
    for _ in range(draw(st.integers(0, 5))):
        q = [draw(st.floats(lo, hi)) for lo, hi in kr6.LIMITS_DEG]
        t = draw(st.floats(0, 0.05))
        text = frame(q, t, draw(st.booleans()))
        wrong = draw(st.sampled_from([None, None, *_FRAME_WRONGS]))
        if wrong == "axis":
            axis = draw(st.sampled_from(AXES))
            text = re.sub(f'{axis}="[^"]*"', f'{axis}="{draw(st.sampled_from(["x", "nan", "inf", "1e9", "-400", ""]))}"',
                          text)
            if axis == "A1" and 'A1=""' in text:  # an empty A1 is the end frame, not a wrong one
                text = text.replace('A1=""', 'A1="?"')
        elif wrong == "markup":  # a value holding what XML escapes: the reason quotes it back
            axis = draw(st.sampled_from(AXES[1:]))
            text = re.sub(f'{axis}="[^"]*"', f'{axis}="{draw(st.sampled_from(["&lt;", "&amp;", "&quot;", "&apos;"]))}x"',
                          text)
        elif wrong == "time":
            text = re.sub(r'T="[^"]*"', f'T="{draw(st.sampled_from(["-1", "1e300", "nan", "", "t"]))}"', text)
        elif wrong == "element":  # (a frame without Pos has no A1: EKI_GetReal finds none, the program EXITs)
            text = text.replace("<Gripper ", "<Other ")
        elif wrong == "root":
            text = text.replace("<Robot>", "<Robot2>", 1)
        elif wrong == "xml":
            # (inside the frame: what comes before its <Robot is skipped as noise between frames)
            cut = draw(st.integers(len("<Robot>") + 1, len(text) - len("</Robot>") - 1))
            text = text[:cut] + draw(st.sampled_from(["<", "&", '"', "<x>", "\x00"])) + text[cut:]
        data = text.encode()
        if wrong == "bytes":
            data = data.replace(b'A2="', b'A2="\xff\xfe')
        elif wrong == "entity":  # entities expanded a thousandfold: expat's limit, no blow-up
            data = (b'<!DOCTYPE Robot [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">'
                    b'<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">]>' + data.replace(b'A3="', b'A3="&c;'))
        parts.append(data + draw(st.sampled_from([b"", b"\n", b"\r\n  "])))
        executed, rejected = executed + (wrong is None), rejected + (wrong is not None)
    ends = draw(st.booleans())
    if ends:
        parts.append(frame(None).encode())
    return b"".join(parts), executed, rejected, ends


@settings(max_examples=40)
@given(_frame_streams())
def test_the_controller_executes_each_right_frame_and_rejects_each_wrong_one(stream):
    """Over a real socket: every right frame is executed, every wrong one rejected with a reason
    (the program goes on), the end frame gives the Ack, a connection closed before it is named;
    nothing a PC sends stops the controller with an exception."""
    data, executed, rejected, ends = stream
    controller = EmulatedController(EkiConfig(), TWIN, port=0)
    ours, theirs = socket.socketpair()
    try:
        theirs.sendall(data)
        theirs.shutdown(socket.SHUT_WR)
        result = controller.handle(ours, "the test")
        ours.shutdown(socket.SHUT_WR)
        answers = b"".join(iter(lambda: theirs.recv(65536), b""))
    finally:
        ours.close(), theirs.close(), controller.stop()
    # Each answer is XML the PC can read, whatever the wrong frame held (its text is in the reason).
    replies = [part + b"</Robot>" for part in answers.split(b"</Robot>")[:-1]]
    assert len(replies) == rejected + ends
    for reply in replies:
        ET.fromstring(reply)
    assert (result is not None) == ends
    if ends:
        assert result.frames == executed and len(result.rejected) == rejected
        assert controller.errors == result.rejected
    else:
        assert len(controller.errors) == rejected + 1 and "dropped before the program ended" in controller.errors[-1]
        assert f"({executed} frames executed)" in controller.errors[-1]


@st.composite
def _eki_files(draw) -> bytes:
    """An EKI configuration as export writes it, with at most one thing edited: the port, a flag,
    an element's Tag or Type, a line dropped, or text that is no XML."""
    text = EkiConfig().to_xml()
    lines = text.splitlines()
    what = draw(st.sampled_from([None, "ip", "port", "flag", "tag", "type", "line", "text", "bytes"]))
    junk = st.sampled_from(["", "x", "-1", "0", "65536", "99999999", "²", "1e3", " 7 ", "1025", "9" * 40]) \
        | st.text(alphabet=st.characters(blacklist_characters='"<>&', blacklist_categories=("Cs",)), max_size=8)
    if what == "ip":  # any text, as XML escapes it
        text = text.replace("<IP>", f"<IP>{escape(draw(st.sampled_from(['<', '&', ' ']) | st.text(max_size=8)))}", 1)
    elif what == "port":
        text = text.replace("<PORT>54600</PORT>", f"<PORT>{draw(junk)}</PORT>")
    elif what == "flag":
        text = text.replace('Set_Flag="1"', f'Set_Flag="{draw(junk)}"')
    elif what in ("tag", "type"):
        elements = [i for i, line in enumerate(lines) if "Type=" in line and "RECEIVE" not in line]
        i = draw(st.sampled_from(elements))
        key = "Tag" if what == "tag" else "Type"
        value = draw(st.sampled_from(["Foo/@x", "Robot", "Robot/Pos[", "Robot/Pos/@", "Robot/@T", "Robot//@A1",
                                      "Robot/Pos/@A7", "REAL", "INT", "BOOL", "DOUBLE"]) | junk)
        lines[i] = re.sub(f'{key}="[^"]*"', f'{key}="{value}"', lines[i])
        text = "\n".join(lines)
    elif what == "line":
        del lines[draw(st.integers(1, len(lines) - 2))]
        text = "\n".join(lines)
    elif what == "text":
        text = draw(st.text(max_size=40))
    data = text.encode()
    if what == "bytes":
        data = data.replace(b"<IP>", b"<IP>\xff", 1)
    return data


_ANY_FRAME = st.one_of(
    st.builds(frame, st.lists(st.floats(-400, 400), min_size=6, max_size=6), st.floats(0, 1), st.booleans()),
    st.just(frame(None)), st.text(max_size=30).map(lambda t: f"<Robot>{t}</Robot>"),
    st.sampled_from(['<Robot><Pos A1="1"/></Robot>', "<Robot/>", '<Robot><Foo x="1"/></Robot>', "<Robot", "x"]))


@given(_eki_files(), st.lists(_ANY_FRAME, max_size=3))
def test_an_eki_file_is_read_whole_or_refused_by_name_and_its_frames_read_or_rejected(data, frames_text):
    """What the controller's configuration holds is checked before a frame is read by it: a port
    and a flag in range, each element an attribute of the frame, with A1-A6 among them; then any
    frame is read or refused as EkiError (the controller's reason). Before, a Set_Flag or port
    that was no number, or a file that was no UTF-8 text, ended `hycosim krl controller` in a
    traceback, and a Tag outside Robot/ raised IndexError out of every frame's reading."""
    try:
        config = EkiConfig.parse(data, "cell.eki")
    except EkiError as exc:
        assert "cell.eki" in str(exc)
        return
    assert 1 <= config.port <= 65535 and 1 <= config.flag <= 1024
    assert all(typ in ("REAL", "INT", "BOOL", "STRING") and tag.startswith("Robot/") and "/@" in tag
               for tag, typ in config.elements)
    assert {f"Robot/Pos/@{a}" for a in AXES} <= {tag for tag, _ in config.elements}
    assert EkiConfig.parse(config.to_xml(), "cell.eki") == config  # written back as it was read
    for text in frames_text:
        try:
            parse_frame(text, config)
        except EkiError:
            pass


def test_the_trials_table_shows_a_dash_where_the_paper_or_the_run_has_no_figure():
    """Table 2 has 30°, 40°, 50° and 60°: another angle (30.5° included) has no paper row, and
    an angle with no grasp has no error or time; the table says "–", never nan."""
    from hycosim.scenario.trials import PAPER, figure_text, paper_figures

    assert paper_figures(30) == paper_figures(30.0) == PAPER[30]
    assert paper_figures(30.5) is None and paper_figures(45) is None
    assert [figure_text(v, "g") for v in paper_figures(50)] == ["5", "15.4", "90"]
    assert figure_text(float("nan"), ".1f") == "–" and figure_text(3.25, ".1f") == "3.2"
