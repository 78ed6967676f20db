"""The reading end of the server and of every node: order, timeouts, and its poll-then-block wait."""

from __future__ import annotations

import threading
import time

import pytest
import zenoh

from hycosim.transport.inbox import LOCAL, Inbox
from hycosim.transport.session import FramePublisher, client_config, open_session, router_config
from tests.helpers import free_endpoint


def _pair():
    endpoint = free_endpoint()
    router = open_session(router_config(endpoint), endpoint)
    client = open_session(client_config(endpoint), endpoint)
    return router, client


@pytest.mark.parametrize("poll", [True, False])
def test_samples_from_another_session_arrive_complete_and_in_order(poll):
    router, client = _pair()
    inbox = Inbox(router, "t/up/**", "t/up/local", poll=poll)
    try:
        pub = FramePublisher(client, "t/up/a", low_latency=True)
        for _ in range(50):  # until the subscription has reached the client
            pub.put(b"ready")
            if inbox.recv(timeout=0.1) is not None:
                break
        while inbox.recv(timeout=0.2) is not None:
            pass
        sent = 3000

        def produce():
            for i in range(sent):
                pub.put(i.to_bytes(4, "little"))
                if i % 500 == 0:
                    time.sleep(0.05)  # gaps long enough for the reader to block

        producer = threading.Thread(target=produce)
        producer.start()
        got = []
        while len(got) < sent:
            item = inbox.recv(timeout=5.0)
            assert item is not None, f"timed out after {len(got)} samples"
            assert item[0] == "t/up/a"
            got.append(int.from_bytes(item[1], "little"))
        producer.join(timeout=5.0)
        assert got == list(range(sent))
    finally:
        inbox.close()
        client.close()
        router.close()


class _Scripted:
    """A channel whose samples come after a given number of empty polls.

    Whether a real sample comes while a reader polls depends on the scheduler; the
    adaptation rule is checked against a script instead, behind a real Inbox.
    """

    def __init__(self, empties: list[int], empty_s: float = 0.0):
        self.empties, self.blocked, self.tries = list(empties), 0, 0
        self.empty_s = empty_s  # how long an empty poll takes: a yield on a loaded machine

    def try_recv(self):
        self.tries += 1
        if self.empties and self.empties[0] > 0:
            self.empties[0] -= 1
            time.sleep(self.empty_s)
            return None
        if self.empties:
            self.empties.pop(0)
            return _Sample()
        return None

    def recv(self):
        self.blocked += 1
        self.empties.pop(0)
        return _Sample()

    def undeclare(self):
        pass


class _Sample:
    key_expr = "t/up/a"
    payload = zenoh.ZBytes(b"x")


def _scripted_inbox(router, poll: bool, empties: list[int], empty_s: float | None = None) -> tuple[Inbox, _Scripted]:
    """``empty_s``: how long each empty poll takes, and the reader's millisecond of polling with
    it; without, polls are counted alone (on a loaded machine three yields can take that long)."""
    inbox = Inbox(router, "t/up/**", "t/up/local", poll=poll)
    inbox._sub.undeclare()
    inbox._sub = script = _Scripted(empties, empty_s or 0.0)
    if empty_s is None:
        inbox._poll_budget_s = 3600.0
    return inbox, script


def test_polls_follow_how_soon_frames_come_and_stop_when_waits_are_long():
    router = open_session(router_config(free_endpoint()), "router")
    try:
        # Frames that come after 3 empty polls: the reader keeps polling and never blocks.
        inbox, script = _scripted_inbox(router, True, [3] * 50)
        for _ in range(50):
            assert inbox.recv(timeout=1.0) == ("t/up/a", b"x")
        assert script.blocked == 0 and inbox.polls == 400  # doubled from 8, capped
        assert inbox.waits == {"queued": 0, "polled": 50, "slept": 0}
        inbox.close()
        # Frames that come only after 10,000 polls: it blocks, halving its polls down to none ...
        inbox, script = _scripted_inbox(router, True, [10_000] * 40)
        for _ in range(40):
            assert inbox.recv(timeout=1.0) == ("t/up/a", b"x")
        assert inbox.polls == 0
        # ... probing again only every 16th wait: one look per wait, 8 polls at the first
        # and at the two probes, not 8 per wait.
        assert script.blocked == 40 and script.tries == 40 + 3 * 8
        assert inbox.waits == {"queued": 0, "polled": 0, "slept": 40}
        inbox.close()
        # Frames already there when it looks are counted as queued, whatever it polls.
        inbox, script = _scripted_inbox(router, True, [0] * 10 + [3] * 5)
        for _ in range(15):
            assert inbox.recv(timeout=1.0) == ("t/up/a", b"x")
        assert inbox.waits == {"queued": 10, "polled": 5, "slept": 0}
        inbox.close()
        # Polls that each give the core away for half a millisecond: the reader blocks after
        # a millisecond of them, though its 8 polls would have caught each frame at the 7th.
        inbox, script = _scripted_inbox(router, True, [6] * 20, empty_s=0.0005)
        for _ in range(20):
            assert inbox.recv(timeout=1.0) == ("t/up/a", b"x")
        assert script.blocked == 20 and inbox.waits == {"queued": 0, "polled": 0, "slept": 20}
        assert script.tries <= 20 + 2 * 4  # one look a wait; at most 3 polls at the first wait and a probe
        inbox.close()
        # A blocking reader never polls.
        inbox, script = _scripted_inbox(router, False, [3] * 20)
        for _ in range(20):
            assert inbox.recv(timeout=1.0) == ("t/up/a", b"x")
        assert script.blocked == 20 and inbox.polls == 0
        assert inbox.waits == {"queued": 0, "polled": 0, "slept": 20}
        inbox.close()
    finally:
        router.close()


def test_a_polling_reader_waiting_long_costs_no_cpu_and_times_out():
    router, client = _pair()
    inbox = Inbox(router, "t/up/**", "t/up/local", poll=True)
    try:
        cpu0, wall0 = time.process_time(), time.monotonic()
        for _ in range(6):
            assert inbox.recv(timeout=0.1) is None
        wall = time.monotonic() - wall0
        cpu = time.process_time() - cpu0
        assert wall >= 0.6
        assert inbox.polls == 0
        # Every thread of the process counts here: a reader that kept polling would use ~all of it.
        assert cpu < 0.5 * wall, f"{cpu:.2f} s of CPU in {wall:.2f} s of waiting"
    finally:
        inbox.close()
        client.close()
        router.close()


def test_recv_on_a_closed_session_raises_instead_of_hanging():
    router, client = _pair()
    inbox = Inbox(router, "t/up/**", "t/up/local")
    client.close()
    router.close()
    try:
        t0 = time.monotonic()
        try:
            inbox.recv(timeout=5.0)
        except zenoh.ZError:
            pass
        else:
            raise AssertionError("recv returned on a closed session")
        assert time.monotonic() - t0 < 2.0
    finally:
        inbox.close()


def _context_switches(thread: threading.Thread) -> int:
    status = open(f"/proc/self/task/{thread.native_id}/status").read()
    return int(status.split("voluntary_ctxt_switches:")[1].split()[0])


def test_the_watchdog_sleeps_between_deadlines_and_keeps_short_ones():
    """The watchdog wakes for a deadline or the quarter-second Ctrl-C tick, not on a poll
    (with 17 processes on 2 cores a 10 ms poll in each cost a fifth of the barrier rate);
    a short timeout set while it sleeps toward a later wake still ends on time."""
    router, client = _pair()
    inbox = Inbox(router, "t/up/**", "t/up/local")
    try:
        time.sleep(0.3)
        before = _context_switches(inbox._watchdog)
        time.sleep(1.0)  # idle
        assert inbox.recv(timeout=1.0) is None  # a long wait
        woken = _context_switches(inbox._watchdog) - before
        assert woken <= 16, f"the watchdog woke {woken} times in 2 s"
        for _ in range(5):
            inbox.inject(b"event")
            assert inbox.recv(timeout=5.0) == (LOCAL, b"event")  # the watchdog now aims at ~0.25 s
            t0 = time.monotonic()
            assert inbox.recv(timeout=0.03) is None
            # not at the watchdog's wake 0.25 s on; the margin is for a loaded machine's scheduling
            assert 0.03 <= time.monotonic() - t0 < 0.2
    finally:
        inbox.close()
        client.close()
        router.close()
