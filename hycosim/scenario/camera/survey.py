"""The camera pipeline run alone over a list of frames (``hycosim camera``): detect the rod in
each, track it, measure the angle error where the true angle is known, and optionally write
the frames with the detection drawn on them to a video."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2

from hycosim.scenario.camera.calibration import Calibration
from hycosim.scenario.camera.detect import RodDetector, annotate
from hycosim.scenario.camera.emulated import Frame
from hycosim.scenario.camera.tracker import Tracker


class VideoWriteError(OSError):
    """An annotated video that cannot be written where it was asked for."""


@dataclass
class Survey:
    """What the pipeline made of the frames."""

    frames: int
    dropped: int  # frames that came without an image
    detected: int  # confident detections the tracker took
    detection_frames_per_s: float
    errors_deg: list[float] = field(default_factory=list)  # |measured - true| where the truth is known


class AnnotatedVideo:
    """A video file of annotated frames, opened at the first frame (its size is the frame's)."""

    def __init__(self, path: Path, fps: float):
        self.path, self.fps = path, fps
        self._writer: cv2.VideoWriter | None = None

    def write(self, image) -> None:
        """Add one frame (BGR); the first opens the file at the frame's size."""
        if self._writer is None:
            h, w = image.shape[:2]
            fourcc = cv2.VideoWriter_fourcc(*("mp4v" if self.path.suffix == ".mp4" else "MJPG"))
            self._writer = cv2.VideoWriter(str(self.path), fourcc, self.fps, (w, h))
            if not self._writer.isOpened():  # OpenCV does not raise: it writes nothing
                raise VideoWriteError(f"{self.path}: cannot write a video there (a missing folder, "
                                      "or a suffix other than .mp4 or .avi?)")
        self._writer.write(image)

    def close(self) -> None:
        """Finish the file (nothing was written where no frame came)."""
        if self._writer is not None:
            self._writer.release()


def survey(frames: list[Frame], calibration: Calibration, video: AnnotatedVideo | None = None) -> Survey:
    """Run detection and tracking over ``frames``; draw each detection into ``video`` if given.
    Raises VideoWriteError when the video cannot be written."""
    detector, tracker = RodDetector(calibration), Tracker()
    errors, detected, t_detect = [], 0, 0.0
    try:
        for frame in frames:
            start = time.perf_counter()
            found = detector.detect(frame.image)
            t_detect += time.perf_counter() - start
            m = tracker.update(frame.t, found)
            if m is not None:
                detected += 1
                if not math.isnan(frame.true_angle):
                    errors.append(abs(math.degrees(m.angle - frame.true_angle)))
            if video is not None and frame.image is not None:
                video.write(annotate(frame.image, found, calibration, f"t={frame.t:.3f}s"))
    finally:
        if video is not None:
            video.close()
    usable = sum(f.image is not None for f in frames)
    return Survey(len(frames), len(frames) - usable, detected, usable / t_detect if t_detect else 0.0, errors)
