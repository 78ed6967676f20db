"""Turning per-frame detections into timestamped measurements of angle and angular velocity."""

from __future__ import annotations

from dataclasses import dataclass

from hycosim.scenario.camera.detect import Detection


@dataclass(frozen=True)
class Measurement:
    """The rod's state as the camera measured it: capture time, angle, angular velocity and the
    detection's confidence."""

    t: float           # capture time, s
    angle: float       # rad
    omega: float       # rad/s (0 until two detections close enough in time)
    confidence: float


class Tracker:
    """Angular velocity by finite difference over consecutive confident detections;
    restarted when detections are more than ``max_gap`` seconds apart (dropped frames)."""

    def __init__(self, max_gap: float = 0.1):
        self.max_gap = max_gap
        self._last: Measurement | None = None

    def update(self, t: float, detection: Detection | None) -> Measurement | None:
        """The measurement of a frame captured at ``t``: the detection's angle and the angular velocity
        since the last detection within ``max_gap``; None where nothing was detected."""
        if detection is None:
            return None
        omega = 0.0
        last = self._last
        if last is not None and 0 < t - last.t <= self.max_gap:
            omega = (detection.angle - last.angle) / (t - last.t)
        m = Measurement(t, detection.angle, omega, detection.confidence)
        self._last = m
        return m
