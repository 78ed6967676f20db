"""A model whose native library aborts the process as it is torn down at exit, after the
node's work is done: glibc's "corrupted double-linked list" from a library's teardown does this."""

import atexit
import os

from hycosim.node.interface import Node


class AbortsAtExit(Node):
    def setup(self, ctx):
        atexit.register(os.abort)  # stands in for a native library's exit-time teardown

    def outputs(self):
        return {"y": 1.0}

    def step(self, t, h, inputs):
        pass
