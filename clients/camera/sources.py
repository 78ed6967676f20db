"""Where frames come from: a video file, a camera device, or the emulated physical rod.

Every source yields :class:`~clients.camera.emulated.Frame` objects with a capture time.
A file or device that cannot be opened raises :class:`CameraError` naming it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import cv2

from clients.camera.emulated import Frame
from clients.node import NodeModelError


class CameraError(NodeModelError):
    """A frame source that cannot be opened or read; names the file or device."""


@dataclass
class VideoFileSource:
    """Frames of a video file, timestamped by their position (frame index / the file's fps)."""

    path: Path

    def __post_init__(self) -> None:
        if not Path(self.path).is_file():
            raise CameraError(f"video file {self.path} does not exist")
        self.capture = cv2.VideoCapture(str(self.path))
        if not self.capture.isOpened():
            raise CameraError(f"video file {self.path} cannot be opened by OpenCV")
        self.fps = self.capture.get(cv2.CAP_PROP_FPS) or 30.0
        self.index = 0

    def frames(self) -> Iterator[Frame]:
        while True:
            ok, image = self.capture.read()
            if not ok:
                return
            yield Frame(self.index / self.fps, image)
            self.index += 1

    def close(self) -> None:
        self.capture.release()


@dataclass
class DeviceSource:
    """Frames of a camera device (``cv2.VideoCapture(index)``), timestamped by the wall clock."""

    index: int

    def __post_init__(self) -> None:
        self.capture = cv2.VideoCapture(self.index)
        if not self.capture.isOpened():
            raise CameraError(f"camera device {self.index} cannot be opened (is it connected? /dev/video{self.index})")
        self.t0 = time.monotonic()

    def frames(self) -> Iterator[Frame]:
        while True:
            ok, image = self.capture.read()
            t = time.monotonic() - self.t0
            if not ok:
                raise CameraError(f"camera device {self.index} stopped delivering frames at t={t:.2f} s")
            yield Frame(t, image)

    def close(self) -> None:
        self.capture.release()
