"""The emulated physical world: a second rod, unlike the twin, seen by a fixed camera.

We have no real rod and no camera, so the "physical" rod is a separate RodModel whose
length, mass, damping, pivot and initial angle may all differ from the twin's, rendered
offscreen by MuJoCo (EGL on the CPU) from a camera facing the swing plane, at its own frame
rate, with Gaussian pixel noise, optional blur and optional dropped frames.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before mujoco is imported: no display here

import math  # noqa: E402
from collections.abc import Iterator  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from hycosim.scenario.camera.calibration import Calibration  # noqa: E402
from hycosim.scenario.rod.model import RodModel, RodParams  # noqa: E402


@dataclass(frozen=True)
class CameraSetup:
    """The emulated camera: image size, field of view, where it stands and looks, its frame rate, and
    the noise, blur and dropped frames it adds."""

    width: int = 320
    height: int = 240
    fovy_deg: float = 45.0
    distance: float = 1.5           # m in front of the swing plane (along +x)
    aim_z: float = 0.72             # m, height the camera looks at
    fps: float = 60.0
    noise_sigma: float = 25.0       # grey levels
    blur_sigma: float = 0.0         # px, Gaussian defocus
    drop_probability: float = 0.0
    seed: int = 0


def visual_mjcf(rod: RodParams, cam: CameraSetup) -> str:
    """A MuJoCo scene of the rod and its pivot as the camera ``cam`` sees them (the model is only
    rendered, never stepped)."""
    px, py, pz = rod.pivot
    return f"""
<mujoco model="physical-rod-view">
  <visual>
    <quality offsamples="0" shadowsize="0"/>
    <global offwidth="{cam.width}" offheight="{cam.height}"/>
    <headlight ambient="0.35 0.35 0.35" diffuse="0.3 0.3 0.3"/>
  </visual>
  <worldbody>
    <light pos="{px + 2} 0 2" dir="-1 0 -0.5" diffuse="0.4 0.4 0.4" castshadow="false"/>
    <geom name="wall" type="box" pos="{px - 0.4} {py} {pz - 0.4}" size="0.01 2.0 2.0" rgba="0.85 0.85 0.82 1"/>
    <geom name="mount" type="box" pos="{px} {py} {pz + 0.02}" size="0.03 0.03 0.02" rgba="0.3 0.3 0.3 1"/>
    <body name="rod" pos="{px} {py} {pz}">
      <joint name="hinge" type="hinge" axis="1 0 0"/>
      <geom name="rod" type="cylinder" fromto="0 0 0 0 0 {-rod.length}" size="{rod.radius}" rgba="0.8 0.08 0.08 1"/>
    </body>
    <camera name="cam" pos="{px + cam.distance} {py} {cam.aim_z}" xyaxes="0 1 0 0 0 1" fovy="{cam.fovy_deg}"/>
  </worldbody>
</mujoco>
"""


def camera_calibration(rod: RodParams, cam: CameraSetup) -> Calibration:
    """The calibration a user would measure: intrinsics from the field of view, the pivot's pixel."""
    f = (cam.height / 2) / math.tan(math.radians(cam.fovy_deg) / 2)
    cx, cy = (cam.width - 1) / 2, (cam.height - 1) / 2
    # Camera looks along −x: image right is world +y, image down is world −z.
    u = cx + f * (rod.pivot[1] - rod.pivot[1]) / cam.distance
    v = cy - f * (rod.pivot[2] - cam.aim_z) / cam.distance
    return Calibration(fx=f, fy=f, cx=cx, cy=cy, pivot_px=(u, v), metres_per_px=cam.distance / f)


@dataclass
class Frame:
    """One captured frame: its simulated capture time, the image (None where it was dropped), and the
    true angle where the source knows it."""

    t: float                 # simulated time of capture, s
    image: np.ndarray | None  # BGR uint8; None: the frame was dropped
    true_angle: float = math.nan
    extra: dict = field(default_factory=dict)


class EmulatedRodCamera:
    """Frames of the physical rod at the camera's rate, on the simulation clock."""

    def __init__(self, rod: RodParams, cam: CameraSetup | None = None):
        self.cam = cam or CameraSetup()
        self.rod = RodModel(rod)
        self.model = mujoco.MjModel.from_xml_string(visual_mjcf(rod, self.cam))
        self.data = mujoco.MjData(self.model)
        self.renderer = mujoco.Renderer(self.model, self.cam.height, self.cam.width)
        self.rng = np.random.default_rng(self.cam.seed)
        self.calibration = camera_calibration(rod, self.cam)
        self.index = 0
        self.render(0.0)  # the first frame compiles shaders (~30 ms): do it before the run
        self.rng = np.random.default_rng(self.cam.seed)

    def render(self, angle: float) -> np.ndarray:
        """One noisy BGR frame with the rod at ``angle``."""
        import cv2

        self.data.qpos[0] = angle
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_camlight(self.model, self.data)  # camera poses are not part of kinematics
        self.renderer.update_scene(self.data, camera="cam")
        rgb = self.renderer.render()
        img = rgb[:, :, ::-1].astype(np.float32)
        if self.cam.blur_sigma > 0:
            img = cv2.GaussianBlur(img, (0, 0), self.cam.blur_sigma)
        if self.cam.noise_sigma > 0:
            img += self.rng.normal(0.0, self.cam.noise_sigma, img.shape).astype(np.float32)
        return np.clip(img, 0, 255).astype(np.uint8)

    def frames_until(self, t: float) -> list[Frame]:
        """The frames captured since the last call, up to simulated time t."""
        return list(self.iter_frames(t))

    def iter_frames(self, t: float) -> Iterator[Frame]:
        """The same frames, each rendered only when asked for: a consumer that processes
        each before taking the next sees them one by one, not as a burst after the last."""
        period = 1.0 / self.cam.fps
        while self.index * period <= t + 1e-12:
            t_frame = self.index * period
            dt = t_frame - self.rod.time
            if dt > 0:
                self.rod.advance(dt)
            self.index += 1
            # The rod integrates in whole 1 ms steps: the capture instant is where it is.
            t_capture = self.rod.time
            if self.cam.drop_probability > 0 and self.rng.random() < self.cam.drop_probability:
                yield Frame(t_capture, None, self.rod.angle)
                continue
            yield Frame(t_capture, self.render(self.rod.angle), self.rod.angle)

    def keep_newest(self, t: float, keep: int) -> int:
        """Of the frames captured up to t and not yet taken, let all but the newest ``keep``
        go by unrendered (a camera driver's ring buffer overwritten by a reader that fell
        behind); returns how many went by."""
        period = 1.0 / self.cam.fps
        newest = math.floor(t / period + 1e-9)
        first_kept = max(self.index, newest - keep + 1)
        skipped = first_kept - self.index
        self.index = first_kept
        return skipped

    def close(self) -> None:
        """Free the renderer."""
        self.renderer.close()
