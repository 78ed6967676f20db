"""A model whose native code crashes mid-run, the way a broken FMU binary or extension does."""

import ctypes

from hycosim.node.interface import Node


class Crashing(Node):
    def outputs(self):
        return {"y": 1.0}

    def step(self, t, h, inputs):
        if t >= 0.05:
            ctypes.string_at(0)  # reads address 0: SIGSEGV
