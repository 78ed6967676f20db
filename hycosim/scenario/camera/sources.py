"""Where frames come from: a video file, a camera device, or the emulated physical rod.

Every source yields :class:`~hycosim.scenario.camera.emulated.Frame` objects with a capture time.
A file or device that cannot be opened raises :class:`CameraError` naming it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import cv2

from hycosim.scenario.camera.emulated import Frame
from hycosim.node.interface import NodeModelError


class CameraError(NodeModelError):
    """A frame source that cannot be opened or read; names the file or device."""


def device_number(source: str) -> int | None:
    """The camera device a source names by its number, or None for a video file. ASCII digits
    only: "²".isdigit() holds, and int() refuses it."""
    return int(source) if source.isascii() and source.isdigit() else None


@dataclass
class VideoFileSource:
    """Frames of a video file, timestamped by their position: ``start_time`` + frame index / the file's fps."""

    path: Path
    start_time: float = 0.0

    def __post_init__(self) -> None:
        if not Path(self.path).is_file():
            raise CameraError(f"video file {self.path} does not exist")
        self.capture = cv2.VideoCapture(str(self.path))
        if not self.capture.isOpened():
            raise CameraError(f"video file {self.path} cannot be opened by OpenCV")
        self.fps = self.capture.get(cv2.CAP_PROP_FPS) or 30.0
        self.index = 0

    def frames(self) -> Iterator[Frame]:
        """The file's frames in order, each stamped by its position; ends at the end of the file."""
        while True:
            ok, image = self.capture.read()
            if not ok:
                return
            yield Frame(self.start_time + self.index / self.fps, image)
            self.index += 1

    def close(self) -> None:
        """Release the file."""
        self.capture.release()


class LiveSource:
    """Frames of a live capture, stamped in simulated time as they are read: ``start_time``
    when the frames are first asked for (a node asks at the run's START), then the monotonic
    clock's seconds since, divided by ``factor`` (a real-time run's wall seconds per simulated
    second). Stamped from when the capture opened instead, every frame would be late by the
    wait for the other nodes to attach."""

    def __init__(self, capture: cv2.VideoCapture, label: str, start_time: float = 0.0, factor: float = 1.0):
        self.capture = capture
        self.label = label
        self.start_time = start_time
        self.factor = factor

    def frames(self) -> Iterator[Frame]:
        """The camera's frames as they come, stamped from when the first was asked for; CameraError
        naming the camera where it stops giving frames."""
        origin = time.monotonic()
        while True:
            ok, image = self.capture.read()
            t = self.start_time + (time.monotonic() - origin) / self.factor
            if not ok:
                raise CameraError(f"{self.label} stopped delivering frames at t={t:.2f} s")
            yield Frame(t, image)

    def close(self) -> None:
        """Release the capture."""
        self.capture.release()


class DeviceSource(LiveSource):
    """Frames of a camera device (``cv2.VideoCapture(index)``), stamped as a LiveSource."""

    def __init__(self, index: int, start_time: float = 0.0, factor: float = 1.0):
        capture = cv2.VideoCapture(index)
        if not capture.isOpened():
            raise CameraError(f"camera device {index} cannot be opened (is it connected? /dev/video{index})")
        super().__init__(capture, f"camera device {index}", start_time, factor)
