"""The helpers a hycosim process keeps itself with (hycosim/core): its heap frozen while a run
steps, waits on descriptors of any number, helper processes that end with their parent."""

from __future__ import annotations

import gc
import os
import subprocess
import sys
import time

import pytest

from hycosim.core.fd_wait import ready
from hycosim.core.heap import set_up_frozen


def test_the_set_up_is_frozen_for_the_run_and_given_back_after_however_it_ends():
    assert gc.get_freeze_count() == 0
    kept = [object() for _ in range(3)]
    with set_up_frozen():
        assert gc.get_freeze_count() >= len(kept)
    assert gc.get_freeze_count() == 0
    with pytest.raises(RuntimeError, match="failed"):
        with set_up_frozen():
            raise RuntimeError("the run failed")
    assert gc.get_freeze_count() == 0


def test_a_wait_on_a_pipe_numbered_past_1024_sees_data_room_a_closed_end_and_times_out(high_descriptors):
    r, w = os.pipe()
    try:
        assert min(r, w) >= 1024
        began = time.monotonic()
        assert not ready(r, timeout=0.2)  # nothing to read: the wait ends at its timeout
        assert 0.15 < time.monotonic() - began < 5.0
        assert ready(w, write=True, timeout=0.0)  # room in the pipe
        os.write(w, b"x")
        assert ready(r, timeout=0.0) and os.read(r, 1) == b"x"
        os.close(w)
        w = -1
        assert ready(r, timeout=1.0) and os.read(r, 1) == b""  # the other end closed
    finally:
        os.close(r)
        if w >= 0:
            os.close(w)


def test_a_helper_ends_with_the_process_it_serves_when_that_is_killed():
    served = subprocess.Popen(["sleep", "60"])
    helper = subprocess.Popen([sys.executable, "-c", (
        "import sys, time\n"
        "from hycosim.core.lifetime import end_with\n"
        "end_with(int(sys.argv[1]))\n"
        "print('watching', flush=True)\n"
        "time.sleep(60)\n"), str(served.pid)], stdout=subprocess.PIPE, text=True)
    try:
        assert helper.stdout.readline().strip() == "watching"
        assert helper.poll() is None
        served.kill()
        served.wait(5)
        assert helper.wait(10) == 0
    finally:
        for p in (served, helper):
            if p.poll() is None:
                p.kill()
                p.wait(5)
