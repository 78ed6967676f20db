"""Node implementations used only by tests (loaded as ``tests.nodes:Class``)."""

from __future__ import annotations

from typing import Any

from hycosim.node.interface import AsyncSource, Node, NodeContext, SimulationEnded


class Text(Node):
    """Every output is a string of ``size`` characters (parameter), ``grown`` characters from
    step ``grow_at`` on where those are given; inputs are ignored."""

    def setup(self, ctx: NodeContext) -> None:
        self.size = int(ctx.parameter("size", 10))
        self.grow_at = ctx.parameter("grow_at", None)
        self.grown = int(ctx.parameter("grown", self.size))
        self.ports = [p.name for p in ctx.outputs]
        self.k = 0

    def outputs(self) -> dict[str, Any]:
        size = self.grown if self.grow_at is not None and self.k >= self.grow_at else self.size
        return {port: (f"{self.k}:" + "x" * size)[:size] for port in self.ports}

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        self.k += 1


class Clock(Node):
    """``y`` = the time reached; a node that cannot save its state (no rollback, no checkpoints)."""

    OUTPUTS = frozenset({"y"})

    def setup(self, ctx: NodeContext) -> None:
        self.t = ctx.start_time

    def outputs(self) -> dict[str, Any]:
        return {"y": self.t}

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        self.t = t + h


class FailingSource(AsyncSource):
    """An asynchronous source sampling y = t at 20 Hz whose sensor fails once t passes ``fail_at``."""

    OUTPUTS = frozenset({"y"})
    PARAMETERS = frozenset({"fail_at"})

    def setup(self, ctx: NodeContext) -> None:
        self.fail_at = float(ctx.parameter("fail_at", 1.0))
        self.t0, self.next_index = ctx.start_time, 0

    def samples_until(self, t: float) -> list[tuple[float, dict[str, Any]]]:
        if t > self.fail_at:
            raise OSError("the sensor stopped answering")
        out = []
        while self.t0 + self.next_index / 20.0 <= t:
            out.append((self.t0 + self.next_index / 20.0, {"y": self.t0 + self.next_index / 20.0}))
            self.next_index += 1
        return out


class FailsAt(Node):
    """A model that raises at t = 0.5 s (its ``at`` parameter), as a model's bug would."""

    OUTPUTS = frozenset({"y"})

    def setup(self, ctx):
        self.at = float(ctx.parameters.get("at", 0.5))
        self.t = ctx.start_time

    def outputs(self):
        return {"y": self.t}

    def step(self, t, h, inputs):
        if t + h > self.at + 1e-9:
            raise ZeroDivisionError("the model divided by zero")
        self.t = t + h


class EndsAt(Node):
    """``y`` = the time reached, plus the input ``u``; ends the simulation at t = ``at`` (0.45 s)
    inside the step that passes it, as an FMU that asks to terminate there, its outputs given there."""

    OUTPUTS = frozenset({"y"})

    def setup(self, ctx):
        self.at = float(ctx.parameters.get("at", 0.45))
        self.t, self.u = ctx.start_time, 0.0

    def outputs(self):
        return {"y": self.t + self.u}

    def step(self, t, h, inputs):
        self.u = inputs["u"]
        if t + h > self.at + 1e-9:
            self.t = self.at
            raise SimulationEnded(self.at, f"the model ends at t={self.at:g} s")
        self.t = t + h


class Static(Node):
    """``y = k·u + b`` at every instant, the start included (its start_feedthrough: y reads u),
    held over a step as a co-simulation FMU's direct feedthrough is; ``k`` 1.0, ``b`` 0.0."""

    INPUTS = frozenset({"u"})
    OUTPUTS = frozenset({"y"})
    FEEDTHROUGH = {"y": frozenset({"u"})}

    def setup(self, ctx: NodeContext) -> None:
        self.k, self.b = float(ctx.parameter("k", 1.0)), float(ctx.parameter("b", 0.0))
        self.y = self.k * (ctx.inputs[0].start_value() if ctx.inputs else 0.0) + self.b

    @property
    def start_feedthrough(self) -> dict[str, list[str]]:
        return {"y": ["u"]}

    def start_inputs(self, inputs: dict[str, Any]) -> None:
        self.y = self.k * inputs["u"] + self.b

    def outputs(self) -> dict[str, Any]:
        return {"y": self.y}

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        self.y = self.k * inputs["u"] + self.b


class SlowStart(Clock):
    """A Clock whose setup takes ``setup_s`` seconds (a model that loads for a while): the run
    cannot start before it has attached."""

    def setup(self, ctx: NodeContext) -> None:
        import time

        time.sleep(float(ctx.parameter("setup_s", 5.0)))
        super().setup(ctx)


class Bytes(Node):
    """At step k: ``label`` the String "n<k>", ``blob`` the Binary bytes k, k+1, k+2 (mod 256),
    ``w`` the Real k / 8."""

    OUTPUTS = frozenset({"label", "blob", "w"})

    def setup(self, ctx: NodeContext) -> None:
        self.k = 0

    def outputs(self) -> dict[str, Any]:
        return {"label": f"n{self.k}", "blob": bytes((self.k + i) % 256 for i in range(3)), "w": self.k / 8}

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        self.k += 1


class Vector(Node):
    """``v``: an array (of its port's shape) whose element i is (i + 1)·t, given as a numpy array;
    ``total``: the sum of the elements of the array input ``a`` at the last step (0 at first)."""

    INPUTS = frozenset({"a"})
    OUTPUTS = frozenset({"v", "total"})

    def setup(self, ctx: NodeContext) -> None:
        import numpy as np

        shape = next(p.shape for p in ctx.outputs if p.name == "v")
        self.base = np.arange(1, int(np.prod(shape)) + 1, dtype=float).reshape(shape)
        self.t, self.total = ctx.start_time, 0.0

    def outputs(self) -> dict[str, Any]:
        return {"v": self.base * self.t, "total": self.total}

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        self.t = t + h
        self.total = sum(inputs.get("a", [])) if "a" in inputs else 0.0

    def get_state(self) -> bytes:
        import struct

        return struct.pack("<dd", self.t, self.total)

    def set_state(self, state: bytes) -> None:
        import struct

        self.t, self.total = struct.unpack("<dd", state)


class VectorOfThree(Vector):
    """A Vector whose ``v`` holds three elements whatever its port's shape says."""

    def outputs(self) -> dict[str, Any]:
        return {"v": [1.0, 2.0, 3.0], "total": self.total}


class Typed(Node):
    """At step k: ``i`` the Integer k·3 − 7, ``b`` the Boolean "k is even", ``r`` the Real k / 3,
    ``s`` the String "s<k>"; input ``u`` (Real) is read into ``r`` as r + u / 1000."""

    OUTPUTS = frozenset({"i", "b", "r", "s"})
    INPUTS = frozenset({"u"})

    def setup(self, ctx: NodeContext) -> None:
        self.k, self.u = 0, 0.0

    def outputs(self) -> dict[str, Any]:
        return {"i": self.k * 3 - 7, "b": self.k % 2 == 0, "r": self.k / 3 + self.u / 1000, "s": f"s{self.k}"}

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        self.k += 1
        self.u = float(inputs.get("u", 0.0))

    def get_state(self) -> bytes:
        import struct

        return struct.pack("<qd", self.k, self.u)

    def set_state(self, state: bytes) -> None:
        import struct

        self.k, self.u = struct.unpack("<qd", state)


class Scheduling(Node):
    """``policy``: the kernel's scheduling policy of the thread that steps the node (Linux's
    ``os.SCHED_*`` number); ``others``: how many of the process's threads (Zenoh's among them)
    have another policy."""

    def setup(self, ctx: NodeContext) -> None:
        self.policy, self.others = -1, -1

    def outputs(self) -> dict[str, Any]:
        return {"policy": self.policy, "others": self.others}

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        import os

        self.policy = os.sched_getscheduler(0)
        policies = []
        for tid in os.listdir("/proc/self/task"):
            try:
                policies.append(os.sched_getscheduler(int(tid)))
            except OSError:  # a thread that ended meanwhile
                pass
        self.others = sum(p != self.policy for p in policies)
