"""The web dashboard: a live run and a finished one in a real browser (Debian's chromium through
Playwright), what the page serves, and the live feed's receivers."""

from __future__ import annotations

import http.client
import json
import shutil
import time
import urllib.request
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hycosim.dashboard.app import check_selection, finite
from hycosim.dashboard.live import LiveFeed, _checked_status, _read_status
from hycosim.dashboard.series import ThinnedSeries
from tests.helpers import descendants, free_port, hycosim, reap, running, spawn, wait_for, write_project
from tests.wire_strategies import deep_json, values

CHROMIUM = shutil.which("chromium")


def _page_up(url: str, timeout: float = 40) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(url, timeout=1) as r:
                if r.status == 200:
                    return
        except OSError:
            time.sleep(0.1)
    raise AssertionError(f"no page at {url} within {timeout} s")


def _catch(tmp_path: Path) -> Path:
    """A falling ball caught by a rising hand at about 0.55 s, paced at half real time (8 s), and
    a pendulum whose pivot and bob the page draws."""
    return write_project(tmp_path / "catch.json", [
        {"nodeName": "ball", "UID": 1, "model": "bouncing_ball", "parameters": {"h0": 2.0, "v0": 0.0, "e": 0.8},
         "input": ["h_in", "v_in"], "output": ["h", "v", {"name": "impacts", "type": "Integer"}]},
        {"nodeName": "hand", "UID": 2, "model": "ramp", "parameters": {"a": 0.2, "b": 0.5}, "output": ["y", "v"]},
        {"nodeName": "arm", "UID": 3, "model": "pendulum", "parameters": {"theta0": 1.0}, "input": ["omega_in"],
         "output": ["theta", "pivot_x", "pivot_z", "bob_x", "bob_z"]},
        {"nodeName": "clock", "UID": 4, "model": "ramp_source", "async": True, "rate": 20, "output": ["y"]},
    ], [{"from": "hand", "to": "ball", "pairs": [["y", "h_in"], ["v", "v_in"]], "activeIn": ["catch"]},
        {"from": "clock.y", "to": "arm.omega_in"}],
        events=[{"name": "catch", "when": "ball.h <= hand.y and hand.y < 1.0", "drives": "ball", "until": "hand.y >= 1.2"}],
        cosim={"stepSize": 0.01, "stopTime": 4.0, "realTime": 2.0}, name="catch")


def _rows_while_running(page, run, runs_dir: Path, nodes: tuple[str, ...], timeout: float = 40) -> None:
    """Wait for the page's row of each node; if the run ends first or the time passes, fail
    with what the run, its server and its dashboard said (a bare selector timeout says nothing)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and run.poll() is None:
        if all(page.query_selector(f"tr[data-node='{n}']") for n in nodes):
            return
        page.wait_for_timeout(100)
    said = []
    for f in sorted(runs_dir.glob("*/*.stderr.txt")):
        said.append(f"--- {f.name}:\n{f.read_text(errors='replace')[-2000:]}")
    exit_status = run.poll()
    err = run.stderr.read() if exit_status is not None and run.stderr else ""
    raise AssertionError(f"the page showed no row for some of {nodes} (run's exit status {exit_status}; "
                         f"page state {page.text_content('#state')!r}); the run said: {err[-2000:]}\n" + "\n".join(said))


def _get(port: int, path: str) -> int:
    """The status of a GET sent as written (no client-side normalisation of ``..``)."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
    conn.request("GET", path)
    status = conn.getresponse().status
    conn.close()
    return status


def _browse_the_finished_run(page, port: int, run_dir: Path) -> None:
    """Issue 59, part 4: a finished run opened without a selection shows its guards' ports
    plotted, its t and mode where it ended, and a list of every port with its value; a click
    plots one, a second takes it off, and the URL keeps the selection."""
    import csv

    page.goto(f"http://127.0.0.1:{port}/")
    page.wait_for_function("window.hycosim.plots['ball.h'] && window.hycosim.plots['hand.y']", timeout=20_000)
    assert page.url.endswith("/?ports=ball.h,hand.y")  # the catch's guards: ball.h <= hand.y, hand.y >= 1.2
    *_, last = csv.DictReader((run_dir / "values.csv").open())
    assert page.text_content("#t") == f"{float(last['t']):.3f}" and page.text_content("#mode") == last["mode"]
    groups = page.eval_on_selector_all("#portlist details", "ds => ds.map(d => d.dataset.node)")
    assert groups == ["ball", "hand", "arm", "clock"]
    shown = page.text_content("#portlist li[data-port='ball.impacts'] .v")
    assert shown == last["ball.impacts"]  # an Integer, as the run ended
    assert "source:" in page.text_content("tr[data-node='clock']")  # the source's row says what it did
    page.fill("#filter", "omega")
    visible = page.eval_on_selector_all("#portlist li:not([hidden])", "ls => ls.map(l => l.dataset.port)")
    assert visible == ["arm.omega_in"]
    page.click("#portlist li[data-port='arm.omega_in'] button")
    page.wait_for_function("window.hycosim.plots['arm.omega_in'] && window.hycosim.plots['arm.omega_in'].drawn > 10",
                           timeout=20_000)
    assert page.url.endswith("?ports=ball.h,hand.y,arm.omega_in")
    page.fill("#filter", "")
    page.click("#portlist li[data-port='hand.y'] button")  # a second click takes it off
    page.wait_for_function("!window.hycosim.plots['hand.y']", timeout=5_000)
    assert page.url.endswith("?ports=ball.h,arm.omega_in")
    assert page.eval_on_selector_all(".plot", "ps => ps.map(p => p.dataset.port)") == ["ball.h", "arm.omega_in"]


@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is installed by `make test`")
def test_a_run_watched_live_and_then_opened_finished_in_a_real_browser(tmp_path):
    from playwright.sync_api import sync_playwright

    port = free_port()
    run = spawn("run", str(_catch(tmp_path)), "--runs-dir", str(tmp_path / "runs"), "--no-progress",
                "--dashboard", "--dashboard-port", str(port))
    board = None
    try:
        _page_up(f"http://127.0.0.1:{port}/")
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto(f"http://127.0.0.1:{port}/?ports=ball.h")
            _rows_while_running(page, run, tmp_path / "runs", ("ball", "hand", "arm", "clock"))
            page.wait_for_function("Number(document.getElementById('step').textContent) > 0", timeout=30_000)
            first = int(page.text_content("#step"))
            page.wait_for_timeout(600)
            assert int(page.text_content("#step")) > first  # updated live, several times a second
            # The port list holds every node's ports, each with its value at the latest point.
            page.wait_for_function("""Number(document.querySelector("#portlist li[data-port='hand.y'] .v")
                                   .textContent) >= 0.5""", timeout=10_000)  # the ramp 0.2·t + 0.5
            page.wait_for_function("window.hycosim.plots['ball.h'] && window.hycosim.plots['ball.h'].drawn > 5",
                                   timeout=20_000)
            page.wait_for_selector("#switches li", timeout=20_000)
            assert "catch" in page.text_content("#switches") and "free → catch" in page.text_content("#switches")
            assert "attached" in page.text_content("#nodes")
            page.wait_for_function("document.getElementById('ages').textContent.startsWith('arm.omega_in: 0.0')",
                                   timeout=10_000)  # a 20 Hz source: its value at most 0.05 s old
            # The twin, drawn from the pendulum's pivot_x/z and bob_x/z: the canvas has ink on it.
            page.wait_for_selector("#scene-box:not([hidden])", timeout=10_000)
            inked = page.evaluate("""() => { const c = document.getElementById('scene');
                const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
                let n = 0; for (let i = 3; i < d.length; i += 4) n += d[i] > 0; return n; }""")
            assert inked > 200
            page.screenshot(path=str(tmp_path / "live.png"))
            assert (tmp_path / "live.png").stat().st_size > 10_000
            out, err = run.communicate(timeout=60)
            assert run.returncode == 0, err
            assert f"dashboard: http://127.0.0.1:{port}/" in err

            run_dir = next((tmp_path / "runs").iterdir())
            port2 = free_port()
            board = spawn("dashboard", str(run_dir), "--port", str(port2))
            _page_up(f"http://127.0.0.1:{port2}/")
            page.goto(f"http://127.0.0.1:{port2}/?ports=ball.h,ball.hh")
            page.wait_for_function("window.hycosim.plots['ball.h'] && window.hycosim.plots['ball.h'].drawn > 100",
                                   timeout=20_000)
            assert "no port 'ball.hh'" in page.text_content("#problems")
            assert "did you mean ball.h" in page.text_content("#problems")
            assert "free → catch" in page.text_content("#switches")
            page.fill("#cursor", "0")  # the time slider: the plot's value at the run's start
            page.dispatch_event("#cursor", "input")
            assert page.text_content("#cursor-t") == "t = 0.0000 s"
            assert page.text_content(".plot .value") == "= 2.000000"  # dropped from 2 m
            page.screenshot(path=str(tmp_path / "finished.png"))
            _browse_the_finished_run(browser.new_page(viewport={"width": 1400, "height": 900}), port2, run_dir)
            browser.close()
        # Nothing outside the package's static folder is served, however the path is spelt.
        for path in ("/static/../meta.json", "/static/%2e%2e/%2e%2e/meta.json", "/static//etc/passwd",
                     f"/static/{run_dir}/meta.json", "/meta.json", "/values.csv"):
            assert _get(port2, path) == 404, path
        assert _get(port2, "/static/dashboard.js") == 200
        # The plot was read in a process of its own. Killed, the dashboard takes it along (and
        # the forkserver it came from): they had stayed behind for good, waiting for work.
        readers = descendants(board.pid)
        assert readers, "the finished run was not read in a process of its own"
        board.kill()
        board.wait(timeout=10)
        wait_for(lambda: not any(running(pid) for pid in readers), 10, "the dashboard's reader processes to end")
    finally:
        reap(run, *([board] if board else []))



@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is installed by `make test`")
def test_a_secured_run_watched_by_two_browsers_through_a_monitors_credentials(tmp_path):
    """A server that requires credentials: a dashboard attached as a monitor user serves two
    browsers at once, both live; one with a wrong password says so on its page and retries; the
    run does not notice any of it."""
    from playwright.sync_api import sync_playwright

    (tmp_path / "creds.txt").write_text("server:srv-pw\nclock:clock-pw\ng:g-pw\nwatcher:w-pw\n")
    (tmp_path / "w.txt").write_text("w-pw\n")
    (tmp_path / "bad.txt").write_text("not-the-password\n")
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}], cosim={"stepSize": 0.01, "stopTime": 8.0, "realTime": True,
                                                 "attachTimeout": 60.0, "linkGrace": 10.0},
        name="secure", security={"credentials": "creds.txt"})
    # linkGrace: in one make test, beside the other worker's tests and this test's browser, node g
    # was lost 4 s into the run (its liveliness token gone after some 2 s without its outputs, as
    # when its 1 s link lease lapses), and the pages waited for nodes that had gone. What this
    # test watches is the dashboard, so the run rides over a lapse as a deployment with a grace would.
    endpoint = json.loads(cfg.read_text())["serverIP"]
    run_dir = tmp_path / "run"
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    good, bad = free_port(), free_port()
    boards = [spawn("dashboard", endpoint, "--project", "secure", "--user", "watcher", "--password-file",
                    str(tmp_path / f), "--port", str(port)) for f, port in (("w.txt", good), ("bad.txt", bad))]
    nodes = []
    try:
        _page_up(f"http://127.0.0.1:{good}/")
        _page_up(f"http://127.0.0.1:{bad}/")
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
            pages = [browser.new_context().new_page() for _ in range(2)]  # two browsers' worth: no shared state
            for page in pages:
                page.goto(f"http://127.0.0.1:{good}/?ports=g.y")
            # The nodes come once the pages are open, so that the run's 8 s are all for watching it:
            # in one CI run the dashboards, the browser and its pages, beside the other worker's
            # tests, came up after the run had ended, and the step counter had stopped for good.
            nodes = [spawn("node", n, str(cfg)) for n in ("clock", "g")]  # passwords from the credentials file
            for page in pages:
                for node in ("clock", "g"):
                    page.wait_for_selector(f"tr[data-node='{node}'] td.attached", timeout=30_000)
                page.wait_for_function("window.hycosim.plots['g.y'] && window.hycosim.plots['g.y'].drawn > 5",
                                       timeout=20_000)
            first = [int(page.text_content("#step")) for page in pages]
            for page, k in zip(pages, first):  # both live: each one's counter moves on
                page.wait_for_function(f"Number(document.getElementById('step').textContent) > {k}", timeout=5_000)
            refused = browser.new_page()
            refused.goto(f"http://127.0.0.1:{bad}/")
            refused.wait_for_function("document.getElementById('state').textContent.includes('cannot reach')",
                                      timeout=20_000)
            assert "retrying" in refused.text_content("#state")
            assert refused.query_selector("tr[data-node]") is None  # it learnt nothing of the run
            browser.close()
        _, err = server.communicate(timeout=60)
        assert server.returncode == 0, err
        assert all(n.wait(timeout=30) == 0 for n in nodes)
    finally:
        reap(server, *nodes, *boards)
    meta = json.loads((run_dir / "meta.json").read_text())
    assert meta["status"] == "completed" and meta["dropped_frames"] == {}


def test_a_dashboard_that_cannot_reach_its_server_says_so_and_keeps_trying():
    feed = LiveFeed(f"tcp/127.0.0.1:{free_port()}", "nothing", retry_s=0.2)
    feed.start()
    try:
        deadline = time.monotonic() + 20
        while "cannot reach" not in feed.snapshot([])["message"] and time.monotonic() < deadline:
            time.sleep(0.05)
        snap = feed.snapshot([])
        assert snap["state"] == "connecting" and "retrying" in snap["message"]
    finally:
        feed.close()


def test_a_dashboard_whose_server_is_busy_answering_others_says_so_and_keeps_trying():
    """A server over its budget of status answers replies 'busy' (server.answer_budget): the
    page says the server is busy, not that no server answers. The server here is a Zenoh peer
    on the status key that only ever says busy."""
    import zenoh

    from hycosim.transport.keys import ProjectKeys
    from hycosim.transport.session import router_config

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(router_config(endpoint)) as server:
        said = []
        busy = server.declare_queryable(ProjectKeys("p").status, lambda q: (
            said.append(1), q.reply_err(b"busy: over 40 status answers a second; ask again")))
        feed = LiveFeed(endpoint, "p", retry_s=0.2)
        feed.start()
        try:
            wait_for(lambda: "busy" in feed.snapshot([])["message"], 20, "the page to say the server is busy")
            snap = feed.snapshot([])
            assert snap["state"] == "connecting" and snap["message"].endswith("busy answering others; retrying")
            count = len(said)
            wait_for(lambda: len(said) > count, 10, "the feed to ask again")
        finally:
            feed.close()
            busy.undeclare()


def test_a_feed_that_fails_on_an_answer_says_so_and_connects_again():
    """Whatever goes wrong while the feed watches a server, its thread stays up: the page says
    the server was lost and shows the run once an answer is taken (a feed thread that died left
    the page waiting on an empty table for good)."""
    import zenoh

    from hycosim.transport.keys import ProjectKeys
    from hycosim.transport.session import router_config

    class FailsOnce(LiveFeed):
        failed = False

        def take(self, status):
            if not self.failed:
                self.failed = True
                raise RuntimeError("a fault in taking an answer")
            super().take(status)

    answer = json.dumps({"project": "p", "nodes": [{"name": "a", "uid": 1, "input": [], "output": ["y"]}],
                         "attached": ["a"], "step": 0}).encode()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(router_config(endpoint)) as server:
        said = server.declare_queryable(ProjectKeys("p").status, lambda q: q.reply(q.key_expr, answer))
        feed = FailsOnce(endpoint, "p", retry_s=0.2)
        messages = []
        feed.watchers.notify = lambda: messages.append(feed.message)
        feed.start()
        try:
            wait_for(lambda: [n["name"] for n in feed.snapshot([])["nodes"]] == ["a"], 20, "the feed to show node a")
            assert any("lost the server" in m and "a fault in taking an answer" in m for m in messages), messages
            assert feed._thread.is_alive()
        finally:
            feed.close()
            said.undeclare()


def test_bad_dashboard_targets_are_refused_by_name(tmp_path):
    (tmp_path / "empty").mkdir()
    res = hycosim("dashboard", str(tmp_path / "empty"), "--port", "0")
    assert res.returncode == 2 and "not a run directory (no meta.json)" in res.stderr and "Traceback" not in res.stderr


class _OtherSite:
    """Another web site on this machine (its own port: another origin): a page that is not the dashboard's."""

    def __init__(self, folder: Path):
        import functools
        import http.server
        import threading

        (folder / "index.html").write_text("<!doctype html><title>another site</title><p>nothing here</p>")
        handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(folder))
        handler.log_message = lambda *a: None
        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        self.origin = f"http://127.0.0.1:{self.server.server_address[1]}"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


_STEAL = """async ([host, port]) => {  // what a page of another site would run: read the run, by feed or by fetch
    const feed = await new Promise((resolve) => {
        let got = null;
        const ws = new WebSocket(`ws://${host}:${port}/ws`);
        ws.onopen = () => ws.send(JSON.stringify({ select: [] }));
        ws.onmessage = (ev) => { got = ev.data; ws.close(); };
        ws.onclose = () => resolve(got === null ? "refused" : "read " + got.slice(0, 40));
        setTimeout(() => resolve(got === null ? "no answer" : "read " + got.slice(0, 40)), 8000);
    });
    let fetched;
    try { fetched = "read " + (await (await fetch(`http://${host}:${port}/api/ports`)).text()).slice(0, 40); }
    catch (e) { fetched = "blocked"; }
    return [feed, fetched];
}"""


@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is installed by `make test`")
def test_pages_of_other_sites_cannot_read_the_run_through_the_users_browser(tmp_path):
    """A dashboard on 127.0.0.1 is within reach of every page the browser shows. In a real
    browser: a page of another site opens the feed (cross-site WebSocket hijacking) and is
    refused, unless the dashboard allows its origin; a name turned to 127.0.0.1 (DNS
    rebinding, here by chromium's resolver rules) is answered 403; the dashboard's own page,
    at 127.0.0.1 or localhost, reads its feed."""
    from playwright.sync_api import sync_playwright

    other = _OtherSite(tmp_path)
    port, allowing_port = free_port(), free_port()
    server = f"tcp/127.0.0.1:{free_port()}"  # nobody there: the page is served, its feed says so
    board = spawn("dashboard", server, "--port", str(port), "--retry", "5")
    allowing = spawn("dashboard", server, "--port", str(allowing_port), "--retry", "5", "--allow-origin", other.origin)
    try:
        _page_up(f"http://127.0.0.1:{port}/")
        _page_up(f"http://127.0.0.1:{allowing_port}/")
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM,
                                        args=["--no-sandbox", "--host-resolver-rules=MAP rebind.test 127.0.0.1"])
            page = browser.new_page()
            for host in ("127.0.0.1", "localhost"):
                page.goto(f"http://{host}:{port}/")
                page.wait_for_function("window.hycosim.snapshot !== null", timeout=20_000)
                feed, fetched = page.evaluate(_STEAL, [host, port])
                assert feed.startswith("read {") and fetched.startswith("read {")  # its own origin: all is its
            page.goto(other.origin + "/")
            assert page.title() == "another site"
            feed, fetched = page.evaluate(_STEAL, ["127.0.0.1", port])
            assert (feed, fetched) == ("refused", "blocked")
            feed, fetched = page.evaluate(_STEAL, ["127.0.0.1", allowing_port])
            assert feed.startswith("read {") and fetched == "blocked"  # allowed to the feed, no further
            answer = page.goto(f"http://rebind.test:{port}/api/ports")
            assert answer.status == 403 and "is not this machine" in page.content()
            assert "rod" not in page.content() and "ports" not in page.content()
            browser.close()
    finally:
        reap(board, allowing)
        other.close()
    assert not board.stderr.read() and not allowing.stderr.read()  # refused quietly, no traceback


_HOSTS = st.one_of(
    st.sampled_from(["127.0.0.1", "127.8.9.10", "localhost", "app.localhost", "[::1]", "::1", "[::1", "evil.test",
                     "127.0.0.1.evil.test", "localhost.evil.test", "0.0.0.0", "[::ffff:127.0.0.1]", "LOCALHOST", ""]),
    st.text(max_size=12)).flatmap(
    lambda name: st.sampled_from([name, f"{name}:8050", f"{name}:0", f"{name}:99999", f"{name}:x", f"{name}:"]))
_ORIGINS = st.none() | st.sampled_from(["null", "file://", "http://evil.test", "https://127.0.0.1:8050/x"]) | \
    _HOSTS.flatmap(lambda h: st.sampled_from([f"http://{h}", f"https://{h}", h])) | st.text(max_size=20)


@given(kind=st.sampled_from(["http", "websocket"]), host=st.none() | _HOSTS, origin=_ORIGINS,
       loopback_only=st.booleans(), allowed=st.lists(_ORIGINS.filter(lambda o: o is not None), max_size=2))
def test_a_request_is_answered_only_when_addressed_here_and_a_feed_only_to_its_own_page(kind, host, origin,
                                                                                       loopback_only, allowed):
    from hycosim.dashboard.origin import is_loopback, normal_origin, refusal, split_host

    permitted = frozenset(o for o in map(normal_origin, allowed) if o)
    why = refusal(kind, host, origin, loopback_only=loopback_only, allowed=permitted)
    assert why is None or (type(why) is str and why)
    where = None if host is None else split_host(host)
    if why is None and loopback_only:  # addressed to this machine, or to a site the user allowed
        assert where is not None and (is_loopback(where[0]) or any(f"//{where[0]}:" in o or f"//[{where[0]}]:" in o
                                                                   for o in permitted))
    if why is None and kind == "websocket" and origin is not None:  # from its own page, or one allowed
        theirs = normal_origin(origin)
        assert theirs is not None
        assert theirs in permitted or (where is not None and split_host(theirs.split("//")[1])[0] == where[0])
    if kind == "http" and host is not None and where is not None and not loopback_only:
        assert why is None  # a page's address never refuses plain requests: CORS keeps their answers from other sites
    if where is not None and is_loopback(where[0]) and (kind == "http" or origin is None):
        assert why is None


_answers = st.fixed_dictionaries(
    {"project": st.just("p") | values},
    optional={"nodes": st.just([{"name": "a", "uid": 1, "input": ["u"], "output": ["y", "z"]},
                                {"name": "g", "uid": 2, "input": [], "output": ["y"]}]) | values,
              "attached": st.lists(st.sampled_from(["a", "g"]) | values, max_size=3) | values,
              "step": st.integers(-1, 10) | values, "t": st.floats() | st.integers(-2, 10 ** 400) | values,
              "window": st.fixed_dictionaries({}, optional={"steps": st.integers(0, 5) | values,
                                                            "held": st.dictionaries(st.sampled_from(["a", "g"]), values),
                                                            "arrival_ms": values}) | values,
              "outputs": st.dictionaries(st.sampled_from(["a", "g", "x"]) | st.text(max_size=2),
                                         st.lists(st.floats() | st.integers(-2, 10 ** 400) | st.booleans() | values,
                                                  max_size=3) | values, max_size=3) | values,
              "inputs": values, "switches": st.lists(st.fixed_dictionaries({"t": st.floats() | values}) | values,
                                                      max_size=3) | values,
              "ages": st.dictionaries(st.text(max_size=3) | st.integers(), st.floats() | values, max_size=3) | values,
              "dropped": values, "mode": values, "lateness_s": values, "point_wall": values, "stopTime": values})


@given(st.lists((_answers | values).map(lambda a: json.dumps(a, default=repr).encode()) | deep_json.map(str.encode)
                | st.binary(max_size=40), max_size=5))
def test_the_live_feed_takes_any_status_answer_without_failing(answers):
    """Whatever answers on the status key (anyone may), the feed uses what fits and the page gets JSON."""
    feed = LiveFeed("tcp/127.0.0.1:1", "p")
    for answer in answers:
        checked = _read_status(answer)
        if checked is None:
            continue
        assert type(checked["project"]) is str and all(type(n["uid"]) is int for n in checked["nodes"])
        feed.take(checked)
    snap = finite(feed.snapshot(feed.ports()))
    json.dumps(snap, allow_nan=False)
    # The port list's values: only ports of nodes the answers declared.
    assert all(k.split(".", 1)[0] in feed.nodes and k in feed.series for k in snap["values"])
    for part in snap["series"].values():
        assert part["from"] == 0 and len(part["t"]) == len(part["y"]) and part["t"] == sorted(part["t"])


@given(values)
def test_a_selection_from_the_page_is_ports_or_problems_with_the_closest_names(raw):
    ports = ["ball.h", "ball.v", "hand.y"]
    chosen, problems = check_selection(raw, ports)
    assert set(chosen) <= set(ports) and len(chosen) <= 16
    if type(raw) is not list or any(p not in ports for p in raw):
        assert problems
    assert check_selection(["ball.hh"], ports)[1][0]["closest"][0] == "ball.h"


def test_a_series_spans_the_whole_run_in_bounded_points_and_forgets_a_step_taken_again():
    s = ThinnedSeries(capacity=100)
    for k in range(100_000):
        s.add(k * 0.001, float(k))
    t, y = s.points()
    assert 100 <= len(t) < 200 and t[0] == 0.0 and t[-1] > 99.0 and t == sorted(t)
    version = s.version
    assert s.since(version, len(t)) is None  # a page that has it all is sent nothing
    s.add(t[-1] + 10.0, 5.0)
    s.add(t[-1] + 20.0, 6.0)
    tail = s.since(version, len(t))
    assert tail is None or (tail["from"] == len(t) and tail["t"][-1] <= t[-1] + 20.0)  # only what it lacks
    back = s.t[-2] + 0.0005  # a step taken again from before the last point drawn: that point is undone
    s.add(back, -1.0)
    assert s.t[-1] == back and s.y[-1] == -1.0 and max(s.t) == back
    assert s.version > version and s.since(version, len(t))["from"] == 0  # held points changed: all anew


def test_a_page_is_sent_only_the_points_it_lacks():
    """The feed pushes each selected series as what the page lacks: everything the first time,
    then only the points after those it holds (all again only when held ones changed)."""
    feed = LiveFeed("tcp/127.0.0.1:1", "p")

    def answer(first: int, last: int) -> dict:
        points = [[k, 0.01 * k, {"a": [float(k)]}, {"a": []}] for k in range(first, last + 1)]
        return _checked_status({"project": "p", "nodes": [{"name": "a", "uid": 1, "input": [], "output": ["y"]}],
                                "attached": ["a"], "step": last, "t": 0.01 * last, "points": points,
                                "window": {"steps": len(points)}})

    feed.take(answer(1, 10))
    first = feed.snapshot(["a.y"])["series"]["a.y"]
    assert first["from"] == 0 and first["y"] == [float(k) for k in range(1, 11)]
    held = {"a.y": (first["version"], len(first["t"]))}
    assert feed.snapshot(["a.y"], held)["series"] == {}  # nothing new: nothing sent
    feed.take(answer(11, 14))
    more = feed.snapshot(["a.y"], held)["series"]["a.y"]
    assert more["from"] == 10 and more["y"] == [11.0, 12.0, 13.0, 14.0]


def test_the_feed_pushes_a_page_when_the_source_changes_and_only_then():
    """A source's change wakes each page's feed at once (no polling: a fast run's cores are the
    run's); a source that does not change is pushed only at the heartbeat."""
    import threading

    import uvicorn
    from websockets.sync.client import connect

    from hycosim.dashboard.app import HEARTBEAT_S, bind, make_app

    feed = LiveFeed("tcp/127.0.0.1:1", "p")  # never started: the test hands it the answers

    def answer(step: int) -> dict:
        return _checked_status({"project": "p", "nodes": [{"name": "a", "uid": 1, "input": [], "output": ["y"]}],
                                "attached": ["a"], "step": step, "t": 0.01 * step,
                                "points": [[step, 0.01 * step, {"a": [float(step)]}, {"a": []}]], "window": {"steps": 1}})

    feed.take(answer(1))
    sock = bind("127.0.0.1", 0)
    server = uvicorn.Server(uvicorn.Config(make_app(feed), log_level="warning", lifespan="off", ws="websockets-sansio"))
    serving = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    serving.start()
    try:
        with connect(f"ws://127.0.0.1:{sock.getsockname()[1]}/ws", open_timeout=10) as ws:
            # Anything the page sends is read or answered: JSON nested deeper than Python's
            # decoder recurses ended the page's feed with a traceback.
            ws.send("[" * 5000)
            ws.send(json.dumps({"select": ["a.y"]}))
            answered, got = False, {}
            while not (answered and "a.y" in got.get("series", {})):  # a push may come before either
                got = json.loads(ws.recv(timeout=5))
                answered |= "not a message the feed knows" in str(got.get("problems"))
            assert got["step"] == 1
            for step in range(2, 8):
                time.sleep(0.15)
                changed = time.monotonic()
                feed.take(answer(step))
                got = json.loads(ws.recv(timeout=5))
                while got.get("step") != step:  # a heartbeat may come between
                    got = json.loads(ws.recv(timeout=5))
                assert time.monotonic() - changed < 0.5 * HEARTBEAT_S, "pushed at the heartbeat, not at the change"
                assert got["series"]["a.y"]["y"][-1] == float(step)
            quiet = time.monotonic()
            pushes = 0
            while time.monotonic() - quiet < 2.5 * HEARTBEAT_S:
                try:
                    ws.recv(timeout=0.2)
                    pushes += 1
                except TimeoutError:
                    pass
            assert 1 <= pushes <= 3  # the heartbeat alone, about once a second
    finally:
        server.should_exit = True
        serving.join(timeout=10)
    assert not serving.is_alive()


@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is installed by `make test`")
def test_a_plot_whose_values_barely_differ_draws_at_once_in_a_real_browser():
    """A series converging (values a few parts in 10^9 apart) is drawn as if flat: uPlot alone
    lays out such an axis for seconds, the page's updates held meanwhile. Each span is drawn
    on a fresh plot in the page of a dashboard (whose server is not there: the page is served)."""
    from playwright.sync_api import sync_playwright

    port = free_port()
    board = spawn("dashboard", f"tcp/127.0.0.1:{free_port()}", "--port", str(port), "--retry", "5")
    try:
        _page_up(f"http://127.0.0.1:{port}/")
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
            page = browser.new_page()
            page.goto(f"http://127.0.0.1:{port}/")
            page.wait_for_function("typeof draw === 'function'")
            for i, (base, spread) in enumerate([(2.0, 7.5e-9), (-5.0, 1e-7), (2.0, 1e-10), (2.0, 0.0), (1.0, 0.5)]):
                took, y_min, y_max = page.evaluate("""async ([port, base, spread]) => {
                    const t = performance.now();
                    draw(port, [[0.27, 0.28, 0.29], [base - spread, base - spread / 2, base]]);
                    await new Promise((r) => setTimeout(r, 0));  // uPlot lays out in a microtask
                    const s = window.hycosim.plots[port].chart.scales.y;
                    return [performance.now() - t, s.min, s.max]; }""", [f"probe{i}", base, spread])
                assert took < 1000, (base, spread, took)
                assert y_min <= base - spread and base <= y_max, (base, spread, y_min, y_max)
                assert y_max - y_min < 10 * max(abs(base), 1)
            browser.close()
    finally:
        reap(board)


@given(tail=st.binary(max_size=300), doc=deep_json)
def test_a_finished_runs_last_row_and_guards_are_read_from_whatever_the_files_hold(tmp_path_factory, tail, doc):
    """The files of a run directory may be torn or edited: the last row and the guards' ports
    are read from anything without an error, and hold only this run's ports."""
    from hycosim.dashboard.finished import guard_ports, last_row

    folder = tmp_path_factory.mktemp("run")
    columns = ["step", "t", "mode", "a.y", "b.u"]
    (folder / "values.csv").write_bytes(b"step,t,mode,a.y,b.u\n0,0.0,free,1.5,x\n" + tail)
    (folder / "project.json").write_text(json.dumps(doc) if not isinstance(doc, dict) else json.dumps(
        {**doc, "events": [{"when": "a.y > 1 and c.z < 2", "until": [doc]}, doc]}))
    end = last_row(folder / "values.csv", columns)
    if b"\n" not in tail:  # the row above is the last whole one
        assert end == {"t": 0.0, "mode": "free", "values": {"a.y": 1.5, "b.u": "x"}}
    else:
        assert set(end) <= {"t", "mode", "values"} and set(end.get("values", {})) <= {"a.y", "b.u"}
    guarded = guard_ports(folder / "project.json", ["a.y", "b.u"])
    if isinstance(doc, dict):  # c.z is no port of this run; whatever else the edited file says is passed over
        assert guarded[0] == "a.y" and set(guarded) <= {"a.y", "b.u"}
    else:
        assert guarded == []
