"""Log lines of several processes sharing one stream stay whole lines."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

from tests.helpers import REPO

_WRITER = """
import sys, time, structlog
from hycosim.core import logs
logs.configure()
time.sleep(max(0.0, float(sys.argv[3]) - time.time()))  # all start writing at once
log = structlog.get_logger().bind(node=sys.argv[1])
for k in range(int(sys.argv[2])):
    log.info("step", step=k, payload="x" * 300)
"""


def test_json_log_lines_of_processes_sharing_stderr_do_not_interleave():
    # Unbuffered, as the images and the launcher run them: every write is a system call.
    env = dict(os.environ, PYTHONUNBUFFERED="1", PYTHONPATH=str(REPO))
    read, write = os.pipe()
    start = time.time() + 3.0
    procs = [subprocess.Popen([sys.executable, "-c", _WRITER, f"n{i}", "20000", str(start)], stderr=write, stdout=subprocess.DEVNULL,
                              env=env, cwd=REPO) for i in range(3)]
    os.close(write)
    with os.fdopen(read, "r") as stream:
        lines = stream.read().splitlines()
    for proc in procs:
        assert proc.wait(timeout=120) == 0
    events = [json.loads(line) for line in lines]  # a torn line fails here
    assert len(events) == 60000
    assert {e["node"] for e in events} == {"n0", "n1", "n2"}
    assert all(e["payload"] == "x" * 300 and e["event"] == "step" for e in events)
