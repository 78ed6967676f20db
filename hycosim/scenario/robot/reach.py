"""Reachability of the rod's swing from the robot's base placement (``hycosim scene reach``).

For rod angles across the swing, IK is solved for the TCP on the grasp point with the
approach perpendicular to the swing plane and the jaws across the rod (as for a grasp),
continuing each solution from its neighbour so the sweep follows one arm configuration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hycosim.scenario.robot import kr6
from hycosim.scenario.robot.scene import RobotScene, SceneParams


@dataclass
class ReachPoint:
    """One rod angle of the sweep: where the grasp point lies there and whether the robot reaches it."""

    angle_deg: float
    position: tuple[float, float, float]
    reachable: bool
    position_error_mm: float
    q_deg: tuple[float, ...]
    limit_margin_deg: float  # smallest distance of any axis to its limit


@dataclass
class ReachReport:
    """The sweep over the rod's swing for one placement of the robot: each angle and whether it is
    reached."""

    params: SceneParams
    points: list[ReachPoint] = field(default_factory=list)

    def reachable_range(self) -> tuple[float, float] | None:
        """The smallest and largest angle reached (degrees), or None where none is."""
        ok = [p.angle_deg for p in self.points if p.reachable]
        return (min(ok), max(ok)) if ok else None

    def fraction_of_swing(self, amplitude_deg: float) -> float:
        """Share of the sampled angles within ±amplitude that are reachable."""
        inside = [p for p in self.points if abs(p.angle_deg) <= amplitude_deg + 1e-9]
        return sum(p.reachable for p in inside) / len(inside) if inside else 0.0


def analyse_reach(params: SceneParams, max_deg: float = 75.0, step_deg: float = 2.5) -> ReachReport:
    """Sweep the rod's angles up to ``max_deg`` on both sides in steps of ``step_deg`` and solve the
    grasp pose's IK at each (see the module's text)."""
    scene = RobotScene(SceneParams(**{**params.__dict__, "check_reach": False}))
    report = ReachReport(params)
    by_angle: dict[float, ReachPoint] = {}
    for sign in (1.0, -1.0):
        q0 = kr6.HOME.copy()
        for a in np.arange(0.0, max_deg + 1e-9, step_deg):
            deg = float(sign * a)
            r = scene.reach(math.radians(deg), q0=q0)
            ok = r.position_error < 2e-3 and r.rotation_error < math.radians(2)
            if ok:
                q0 = r.q
            margin = float(np.min(np.minimum(r.q - kr6.LIMITS[:, 0], kr6.LIMITS[:, 1] - r.q)))
            pos = tuple(float(v) for v in np.asarray(params.pivot) + params.grasp_distance *
                        np.array([0.0, math.sin(math.radians(deg)), -math.cos(math.radians(deg))]))
            point = ReachPoint(deg, pos, ok, 1000 * r.position_error, tuple(np.degrees(r.q).round(1)),
                               math.degrees(margin))
            if deg not in by_angle or (ok and not by_angle[deg].reachable):
                by_angle[deg] = point
    report.points = [by_angle[k] for k in sorted(by_angle)]
    return report


def plot_reach(report: ReachReport, out: Path) -> Path:
    """Plot the report's reached and unreached angles into ``out`` (PNG); returns ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p = report.params
    fig, ax = plt.subplots(figsize=(7, 6))
    ys = [pt.position[1] for pt in report.points]
    zs = [pt.position[2] for pt in report.points]
    colors = ["tab:green" if pt.reachable else "tab:red" for pt in report.points]
    ax.plot([p.pivot[1]], [p.pivot[2]], "ks", label="pivot")
    for pt in report.points[:: max(1, len(report.points) // 12)]:
        ax.plot([p.pivot[1], pt.position[1]], [p.pivot[2], pt.position[2]], color="0.85", lw=0.8)
    ax.scatter(ys, zs, c=colors, s=22, zorder=3)
    ax.scatter([], [], c="tab:green", label="grasp point reachable")
    ax.scatter([], [], c="tab:red", label="not reachable")
    shoulder = np.asarray(p.base) + np.array([0.025, 0.0, 0.400])
    ax.plot([shoulder[1]], [shoulder[2]], "b^", label=f"robot A2 axis (x={shoulder[0]:.3f} m)")
    ax.set_xlabel("y (m)")
    ax.set_ylabel("z (m)")
    ax.set_aspect("equal")
    rng = report.reachable_range()
    ax.set_title(f"KR6 R700 reach over the rod's swing (plane x = {p.pivot[0]:.2f} m)\n"
                 + (f"reachable from {rng[0]:+.1f}° to {rng[1]:+.1f}°" if rng else "nothing reachable"))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
