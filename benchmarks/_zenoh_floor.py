"""The floor for a Zenoh barrier in Python: one step message out, N replies back, nothing else.

Same transport choices as hycosim (its router and client session configs, so the
low-latency transport; its Zenoh runtime threads; BLOCK + express publishers; the server's
Unix socket beside its TCP port, which the nodes take where they block, as hycosim's do; the
same reader, an Inbox in the main thread that polls before it blocks as hycosim's
waitStrategy says; its nodes scheduled as batch work where hycosim's nodeScheduling would
schedule them so; msgpack) but no config, routing, checking or recording.
"""

import os
import subprocess
import sys
import time

import msgpack
import zenoh

from hycosim.core.schema import polls_before_blocking
from hycosim.core.scheduling import batch_nodes, schedule_as_batch
from hycosim.transport.inbox import Inbox
from hycosim.transport.session import client_config, prefer_shared_runtime, reach, router_config, server_socket


def _conf(endpoint: str, router: bool, polls: bool = False) -> zenoh.Config:
    # hycosim's choice (coSimulation.localSocket, on by default), by the same functions.
    if router:
        return router_config(endpoint, local=server_socket(endpoint)[0])
    return client_config(endpoint if polls else reach(endpoint, 10.0))


def node(endpoint: str, i: int, polls: bool) -> None:
    """Node ``i`` of the floor: answer each step message with 0.5·u + 1 until the stop message."""
    with zenoh.open(_conf(endpoint, False, polls)) as s:
        pub = s.declare_publisher(f"floor/out/{i}", congestion_control=zenoh.CongestionControl.BLOCK, express=True)
        inbox = Inbox(s, "floor/step/**", f"floor/step/local{i}", poll=polls)
        s.liveliness().declare_token(f"floor/alive/{i}")
        while True:
            m = msgpack.unpackb(inbox.recv(60.0)[1])
            if m[0] < 0:
                break
            pub.put(msgpack.packb([m[0], i, 0.5 * m[1][i] + 1.0]))
        inbox.close()


def server(endpoint: str, n: int, steps: int, wait_strategy: str) -> float:
    """The floor's server: start ``n`` nodes, wait for their tokens, run ``steps`` barrier steps and
    return the steps/s."""
    polls = polls_before_blocking(wait_strategy, n + 1, os.cpu_count())
    with zenoh.open(_conf(endpoint, True)) as s:
        pub = s.declare_publisher("floor/step", congestion_control=zenoh.CongestionControl.BLOCK, express=True)
        inbox = Inbox(s, "floor/out/**", "floor/out/local", poll=polls)
        alive = s.liveliness().declare_subscriber("floor/alive/*", zenoh.handlers.FifoChannel(64), history=True)
        batch = str(int(batch_nodes("auto", n + 1, os.cpu_count(), paced=False)))
        procs = [subprocess.Popen([sys.executable, __file__, "node", endpoint, str(i), str(int(polls)), batch])
                 for i in range(n)]
        seen = set()
        while len(seen) < n:
            seen.add(str(alive.recv().key_expr))
        y = [1.0] * n
        t0 = time.perf_counter()
        for k in range(steps):
            pub.put(msgpack.packb([k, [y[(i - 1) % n] for i in range(n)]]))
            for _ in range(n):
                _, i, value = msgpack.unpackb(inbox.recv(60.0)[1])
                y[i] = value
        rate = steps / (time.perf_counter() - t0)
        pub.put(msgpack.packb([-1, []]))
        for p in procs:
            p.wait(timeout=30)
        inbox.close()
    return rate


if __name__ == "__main__":
    prefer_shared_runtime()  # the nodes it starts inherit it
    if sys.argv[1] == "node":
        if sys.argv[5] == "1":  # before Zenoh starts its threads, which take this thread's policy
            schedule_as_batch()
        node(sys.argv[2], int(sys.argv[3]), sys.argv[4] == "1")
    else:
        print(server(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]), flush=True)
