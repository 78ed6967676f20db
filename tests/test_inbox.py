"""The reading end of the server and of every node: order, timeouts, and its poll-then-block wait."""

from __future__ import annotations

import threading
import time

import zenoh

from fmu_bridge.inbox import Inbox
from fmu_bridge.session import FramePublisher, client_config, open_session, router_config
from tests.helpers import free_endpoint


def _pair():
    endpoint = free_endpoint()
    router = open_session(router_config(endpoint), endpoint)
    client = open_session(client_config(endpoint), endpoint)
    return router, client


def test_samples_from_another_session_arrive_complete_and_in_order_while_polling_and_blocking():
    router, client = _pair()
    inbox = Inbox(router, "t/up/**", "t/up/local")
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


def test_a_long_wait_blocks_instead_of_polling_and_times_out():
    router, client = _pair()
    inbox = Inbox(router, "t/up/**", "t/up/local")
    try:
        for _ in range(20):  # a fast stream grows the number of polls before blocking ...
            inbox.inject(b"x")
            assert inbox.recv(timeout=1.0) == ("t/up/local", b"x")
        assert inbox.polls > 8
        cpu0, wall0 = time.process_time(), time.monotonic()
        for _ in range(6):  # ... and waits that end in a timeout shrink it again
            assert inbox.recv(timeout=0.1) is None
        wall = time.monotonic() - wall0
        cpu = time.process_time() - cpu0
        assert wall >= 0.6
        assert inbox.polls == 8
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
