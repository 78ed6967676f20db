"""The camera as an asynchronous hycosim node: it publishes measurements, it does not step.

Parameters: ``source`` (``emulated``, a video file path, or a device index), camera setup
(``width``, ``height``, ``fps``, ``noise_sigma``, ``blur_sigma``, ``drop_probability``,
``seed``), ``physical`` (the emulated rod's parameters, as for the rod node, differing
from the twin's as much as you like) and ``calibration`` (a JSON file; the emulated source
calibrates itself). Outputs: ``meas_angle``, ``meas_omega``, ``meas_t`` (capture time),
``meas_conf``, ``meas_valid``, ``latency`` (s from capture to publication, measured),
and ``true_angle`` (the emulated rod's angle: ground truth for tests and benchmarks).

A frame without a confident detection emits no sample: the server keeps the last one and
records its age. Each frame's sample is published as soon as it is measured. Like a camera
driver's ring buffer, the node keeps only the newest ``buffer_frames`` (2) frames: when it
falls behind (a loaded machine), older frames go by unmeasured rather than arriving late
(a late measurement is worth less to the observer than a fresh one); how many is logged.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from typing import Any

import structlog

from hycosim.scenario.camera.calibration import Calibration
from hycosim.scenario.camera.detect import RodDetector
from hycosim.scenario.camera.emulated import CameraSetup, EmulatedRodCamera, Frame
from hycosim.scenario.camera.sources import CameraError, DeviceSource, VideoFileSource, device_number
from hycosim.scenario.camera.tracker import Tracker
from hycosim.node.interface import AsyncSource, NodeContext
from hycosim.scenario.rod.node import ROD_PARAMETERS, rod_params


def camera_setup(parameters: dict[str, Any]) -> CameraSetup:
    """The emulated camera's setup from a node's parameters, each unset one at its default."""
    d = CameraSetup()
    return CameraSetup(width=int(parameters.get("width", d.width)), height=int(parameters.get("height", d.height)),
                       fps=float(parameters.get("fps", parameters.get("rate", d.fps))),
                       noise_sigma=float(parameters.get("noise_sigma", d.noise_sigma)),
                       blur_sigma=float(parameters.get("blur_sigma", d.blur_sigma)),
                       drop_probability=float(parameters.get("drop_probability", d.drop_probability)),
                       seed=int(parameters.get("seed", d.seed)))


class CameraNode(AsyncSource):
    """The camera as an asynchronous node: frames from an emulated camera, a video file or a device, the
    rod found in each and tracked, its angle and angular velocity sent as samples as they are
    measured."""

    PARAMETERS = frozenset({"source", "width", "height", "fps", "rate", "noise_sigma", "blur_sigma",
                            "drop_probability", "seed", "physical", "calibration", "buffer_frames"})
    OUTPUTS = frozenset({"meas_angle", "meas_omega", "meas_t", "meas_conf", "meas_valid", "latency", "true_angle"})

    def setup(self, ctx: NodeContext) -> None:
        params = ctx.parameters
        physical = params.get("physical", {})
        unknown = sorted(set(physical) - ROD_PARAMETERS) if isinstance(physical, dict) else None
        if unknown is None or unknown:
            raise CameraError(f"camera node {ctx.name!r}: parameters.physical " + (
                f"has no parameter {', '.join(map(repr, unknown))} (the rod's parameters: "
                f"{', '.join(sorted(ROD_PARAMETERS))})" if unknown else "must be an object of the rod's parameters"))
        source = str(params.get("source", "emulated"))
        self.emulated: EmulatedRodCamera | None = None
        self.stream = None
        if source == "emulated":
            self.emulated = EmulatedRodCamera(rod_params(physical), camera_setup(params))
            calibration = self.emulated.calibration
        else:
            cal_file = params.get("calibration")
            if not cal_file:
                raise CameraError(f"camera node {ctx.name!r}: a real source needs 'calibration' (a JSON file)")
            calibration = Calibration.load(ctx.project_dir / cal_file)
            device = device_number(source)
            if device is not None:
                if ctx.real_time is None:
                    raise CameraError(f"camera node {ctx.name!r}: camera device {source} is live, so the run must be "
                                      'paced by the clock: set "realTime" in the project\'s coSimulation')
                self.stream = DeviceSource(device, ctx.start_time, ctx.real_time).frames()
            else:
                self.stream = VideoFileSource(ctx.project_dir / source, ctx.start_time).frames()
        self.detector = RodDetector(calibration)
        self.tracker = Tracker()
        self.buffer_frames = int(params.get("buffer_frames", 2))
        self.skipped = 0
        self.log = structlog.get_logger("camera").bind(node=ctx.name)

    def _frames_until(self, t: float) -> Iterator[Frame]:
        if self.emulated is not None:
            if self.buffer_frames > 0:
                self.skipped += self.emulated.keep_newest(t, self.buffer_frames)
            yield from self.emulated.iter_frames(t)
            return
        for frame in self.stream:
            yield frame
            if frame.t >= t:
                break

    def samples_until(self, t: float) -> Iterator[tuple[float, dict[str, Any]]]:
        for frame in self._frames_until(t):
            captured = time.perf_counter()
            m = self.tracker.update(frame.t, self.detector.detect(frame.image))
            if m is None:
                continue
            yield m.t, {"meas_angle": m.angle, "meas_omega": m.omega, "meas_t": m.t,
                        "meas_conf": m.confidence, "meas_valid": True,
                        "latency": time.perf_counter() - captured,
                        "true_angle": frame.true_angle if not math.isnan(frame.true_angle) else m.angle}

    def teardown(self) -> None:
        if self.skipped:
            self.log.warning("camera fell behind", frames_skipped=self.skipped)
        if self.emulated is not None:
            self.emulated.close()
