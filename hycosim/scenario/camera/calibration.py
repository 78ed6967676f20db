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
from typing import Annotated

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from hycosim.core import json_text


class CalibrationError(ValueError):
    """A calibration that cannot be read or computed; names the file or image."""


@dataclass(frozen=True)
class Calibration:
    """A camera's view of the swing plane: its intrinsics (focal lengths and principal point, px), where
    the pivot lies in the image, the metres a pixel spans there, and whether the image is mirrored."""

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
        """Write the calibration as JSON to ``path`` (what :meth:`load` reads)."""
        path.write_text(json.dumps(asdict(self), indent=2))

    @staticmethod
    def load(path: Path) -> "Calibration":
        """A calibration :meth:`save` wrote; CalibrationError naming the file and the first field
        that is wrong (a user's file: each number finite, the focal lengths and scale above 0)."""
        try:
            d = _CalibrationFile.model_validate(json_text.loads(Path(path).read_bytes()))
        except (OSError, ValueError) as exc:  # ValidationError is a ValueError
            raise CalibrationError(f"{path}: not a camera calibration ({_first_problem(exc)})") from None
        return Calibration(fx=d.fx, fy=d.fy, cx=d.cx, cy=d.cy, pivot_px=(d.pivot_px[0], d.pivot_px[1]),
                           metres_per_px=d.metres_per_px, flip=d.flip)


_Finite = Annotated[float, Field(allow_inf_nan=False)]
_Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]


class _CalibrationFile(BaseModel):
    """A calibration file's fields, as :meth:`Calibration.save` writes them (strict: no "1" for 1)."""

    model_config = ConfigDict(extra="forbid", strict=True)
    fx: _Positive
    fy: _Positive
    cx: _Finite
    cy: _Finite
    pivot_px: Annotated[list[_Finite], Field(min_length=2, max_length=2)]
    metres_per_px: _Positive
    flip: bool = False


def _first_problem(exc: Exception) -> str:
    if isinstance(exc, ValidationError):
        e = exc.errors()[0]
        if not e["loc"]:
            return "a JSON object is expected"
        return f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}"
    return getattr(exc, "strerror", None) or str(exc)


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
