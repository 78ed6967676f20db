"""Rod detection with OpenCV: the angle of a red rod in one frame, with a confidence.

Gaussian blur 5×5 → HSV red threshold → morphological open → largest contour →
``cv2.fitLine``. Without the blur, the line fit breaks down at noise σ = 25 (measured
here). A frame whose best blob is too small, too thick or too far from the pivot yields
no detection rather than a wrong angle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from hycosim.scenario.camera.calibration import Calibration


@dataclass(frozen=True)
class Detection:
    """The rod found in one frame: its angle (rad), a confidence (0..1) and its length in pixels."""

    angle: float          # rad
    confidence: float     # 0..1
    length_px: float
    centroid: tuple[float, float]
    endpoints: tuple[tuple[float, float], tuple[float, float]]


class RodDetector:
    """Finds the rod in a frame (see the module's text); a blob shorter than ``min_length_px`` or a fit
    less sure than ``min_confidence`` gives no detection."""

    def __init__(self, calibration: Calibration, min_length_px: float = 25.0, min_confidence: float = 0.5):
        self.cal = calibration
        self.min_length_px = min_length_px
        self.min_confidence = min_confidence
        self._kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))

    def _mask(self, image: np.ndarray) -> np.ndarray:
        hsv = cv2.cvtColor(cv2.GaussianBlur(image, (5, 5), 0), cv2.COLOR_BGR2HSV)
        # Red wraps around hue 0.
        low = cv2.inRange(hsv, (0, 110, 60), (12, 255, 255))
        high = cv2.inRange(hsv, (168, 110, 60), (180, 255, 255))
        return cv2.morphologyEx(low | high, cv2.MORPH_OPEN, self._kernel)

    def _blob(self, image: np.ndarray | None) -> np.ndarray | None:
        """Pixels of the largest red blob, or None."""
        if image is None or image.size == 0:
            return None
        contours, _ = cv2.findContours(self._mask(image), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        if not contours:
            return None
        blob = max(contours, key=cv2.contourArea)
        return blob if len(blob) >= 5 and cv2.contourArea(blob) > 0 else None

    def segment(self, image: np.ndarray) -> tuple[tuple[float, float], tuple[float, float]] | None:
        """Endpoints of the rod's image line (largest red blob), or None."""
        blob = self._blob(image)
        if blob is None:
            return None
        vx, vy, x0, y0 = cv2.fitLine(blob, cv2.DIST_L2, 0, 0.01, 0.01).ravel()
        pts = blob.reshape(-1, 2).astype(np.float64)
        s = (pts[:, 0] - x0) * vx + (pts[:, 1] - y0) * vy
        a, b = s.min(), s.max()
        return (float(x0 + a * vx), float(y0 + a * vy)), (float(x0 + b * vx), float(y0 + b * vy))

    def detect(self, image: np.ndarray | None) -> Detection | None:
        """The rod's angle in this frame, or None when no confident detection."""
        blob = self._blob(image)
        if blob is None:
            return None
        vx, vy, x0, y0 = (float(v) for v in cv2.fitLine(blob, cv2.DIST_L2, 0, 0.01, 0.01).ravel())
        pts = blob.reshape(-1, 2).astype(np.float64)
        along = (pts[:, 0] - x0) * vx + (pts[:, 1] - y0) * vy
        across = np.abs(-(pts[:, 0] - x0) * vy + (pts[:, 1] - y0) * vx)
        length = float(along.max() - along.min())
        if length < self.min_length_px:
            return None
        pu, pv = self.cal.pivot_px
        # Orient the line away from the pivot; the rod must point back at it.
        if (x0 - pu) * vx + (y0 - pv) * vy < 0:
            vx, vy = -vx, -vy
        miss = abs(-(pu - x0) * vy + (pv - y0) * vx)  # pivot's distance from the line, px
        width = 2 * float(np.percentile(across, 90))
        slender = min(1.0, length / (8 * max(width, 1.0)))
        aimed = max(0.0, 1.0 - miss / (0.15 * length))
        confidence = slender * aimed
        if confidence < self.min_confidence:
            return None
        ends = ((x0 + along.min() * vx, y0 + along.min() * vy), (x0 + along.max() * vx, y0 + along.max() * vy))
        return Detection(self.cal.angle_of((vx, vy)), confidence, length, (x0, y0), ends)


def annotate(image: np.ndarray, detection: Detection | None, cal: Calibration, text: str = "") -> np.ndarray:
    """A copy of the frame with the detected rod line, the pivot and a caption drawn on it."""
    out = image.copy()
    pu, pv = (int(round(c)) for c in cal.pivot_px)
    cv2.circle(out, (pu, pv), 4, (255, 200, 0), -1)
    if detection is not None:
        (u0, v0), (u1, v1) = detection.endpoints
        cv2.line(out, (int(u0), int(v0)), (int(u1), int(v1)), (0, 255, 0), 2)
        text = f"{math.degrees(detection.angle):+6.2f} deg  conf {detection.confidence:.2f}  {text}"
    else:
        text = f"no detection  {text}"
    cv2.putText(out, text, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 2, cv2.LINE_AA)
    cv2.putText(out, text, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    return out
