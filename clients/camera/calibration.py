"""Image ↔ world for the camera that watches the rod's swing plane.

The camera faces the swing plane squarely (optical axis along the hinge), so angles in
the plane appear undistorted in the image: the rod's angle is the angle of its image line
about the pivot's pixel, measured from straight down, positive towards image right
(world +y). What needs calibrating is the pivot's pixel, the image scale and the sign.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np


class CalibrationError(ValueError):
    """A calibration that cannot be read or computed; names the file or image."""


@dataclass(frozen=True)
class Calibration:
    fx: float
    fy: float
    cx: float
    cy: float
    pivot_px: tuple[float, float]
    metres_per_px: float
    flip: bool = False  # True when image right is world −y (camera behind the plane)

    def angle_of(self, direction: tuple[float, float]) -> float:
        """Rod angle from an image direction (du, dv) pointing from the pivot along the rod."""
        du, dv = direction
        if self.flip:
            du = -du
        return math.atan2(du, dv)

    def save(self, path: Path) -> None:
        path.write_text(json.dumps(asdict(self), indent=2))

    @staticmethod
    def load(path: Path) -> "Calibration":
        try:
            d = json.loads(Path(path).read_text())
            return Calibration(**{**d, "pivot_px": tuple(d["pivot_px"])})
        except (OSError, json.JSONDecodeError, TypeError, KeyError) as exc:
            raise CalibrationError(f"{path}: not a camera calibration ({exc})") from None


def calibrate_from_image(image: np.ndarray, detector_factory, known_angle: float = 0.0,
                         rod_length_m: float = 0.6, source: str = "<image>") -> Calibration:
    """Calibrate from one image of the rod at a known angle (at rest: 0).

    The detected rod line gives the pivot's pixel (its upper end, where it meets the mount)
    and the scale (its length in pixels against ``rod_length_m``).
    """
    h, w = image.shape[:2]
    provisional = Calibration(fx=1.0, fy=1.0, cx=(w - 1) / 2, cy=(h - 1) / 2, pivot_px=((w - 1) / 2, 0.0),
                              metres_per_px=1.0)
    found = detector_factory(provisional).segment(image)
    if found is None:
        raise CalibrationError(f"{source}: no rod found to calibrate from")
    (u0, v0), (u1, v1) = found
    top, bottom = ((u0, v0), (u1, v1)) if v0 < v1 else ((u1, v1), (u0, v0))
    length_px = math.hypot(bottom[0] - top[0], bottom[1] - top[1])
    seen = math.atan2(bottom[0] - top[0], bottom[1] - top[1])
    flip = abs(seen - known_angle) > abs(-seen - known_angle) + 1e-9
    return Calibration(fx=1.0, fy=1.0, cx=(w - 1) / 2, cy=(h - 1) / 2, pivot_px=top,
                       metres_per_px=rod_length_m / length_px, flip=flip)
