"""The paper's own formulation of the grasp task, as a baseline for the engineered one.

State (the paper, section 2.4: "the robot's coordinates and the angles of each axis, as well
as the coordinates and offset angles of the object model"): the TCP position (m), the six
joint angles (rad), the rod's grasp-point position (m) and its angle (rad): 13 numbers.
Action ("the angular positions of the robot's motion axes"): six joint targets, each in
[-1, 1] across its axis's range. Reward: Equation 6, as for the engineered task, except that
any grasp reaches the object (the paper names no tolerance, and jaws closed by distance alone
rarely meet the grasp point within the engineered task's 3 mm). The paper
does not say how the jaws are commanded; here they close when the TCP is within
``REFLEX_DISTANCE`` of the rod's grasp point (no prediction of where the rod will be), and
open again if they closed on nothing.

Learning is plain DDPG from scratch: no demonstrations, no cloning, Gaussian exploration.
It shares the rod, the robot scene, the episode rules and the evaluation with
:class:`hycosim.scenario.policy.env.GraspEnv`; it is reported beside the engineered policy's
training (``benchmarks/policy_baseline.py``), not tuned to a target.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import gymnasium as gym
import numpy as np

from hycosim.scenario.policy.ddpg import DDPG, DDPGConfig, ReplayBuffer
from hycosim.scenario.policy.env import GraspEnv
from hycosim.scenario.policy.features import REFLEX_DISTANCE, missed
from hycosim.scenario.robot import kr6

PAPER_OBS_DIM = 13
PAPER_ACT_DIM = 6


def joint_targets(action: np.ndarray) -> np.ndarray:
    """Joint targets from an action in [-1, 1]^6, linear across each axis's range."""
    a = np.clip(np.asarray(action, dtype=float), -1.0, 1.0)
    low, high = kr6.LIMITS[:, 0], kr6.LIMITS[:, 1]
    return low + (a + 1.0) / 2.0 * (high - low)


class PaperGraspEnv(GraspEnv):
    """The grasp episode with the paper's state and action (see the module docstring)."""

    grasp_tolerance = float("inf")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (PAPER_OBS_DIM,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (PAPER_ACT_DIM,), np.float32)

    def _obs(self) -> np.ndarray:
        o = self.out
        return np.asarray([*o.tcp, *o.q, *self.rod.outputs().grasp, self.rod.angle], dtype=np.float32)

    def step(self, action: np.ndarray):
        targets, self.pending = self.pending, joint_targets(action)
        if self.grip and missed(self.out.gap, self.rod_params.radius):
            self.grip = False
        grasp = self.rod.outputs().grasp
        self.grip = self.grip or float(np.linalg.norm(self.out.tcp - grasp)) < REFLEX_DISTANCE
        return self._advance(targets)


def paper_agent(seed: int) -> DDPG:
    """Plain DDPG for the paper's formulation: no cloning terms, Gaussian noise on every axis."""
    cfg = DDPGConfig(seed=seed, actor_lr=1e-4, noise=0.2, choice=False, bc_weight=0.0, anchor_weight=0.0)
    return DDPG(cfg, obs_dim=PAPER_OBS_DIM, act_dim=PAPER_ACT_DIM)


def train_paper(seconds: float, seed: int = 0, eval_every: int = 50, eval_trials: int = 5,
                progress: Callable[[dict], None] | None = None) -> dict:
    """DDPG from scratch on :class:`PaperGraspEnv` for ``seconds`` of wall time; the
    evaluations (success per release angle, as for the engineered policy) against time."""
    from hycosim.scenario.policy.train import EVAL_ANGLES

    report = progress or (lambda _: None)
    env, agent = PaperGraspEnv(), paper_agent(seed)
    buffer = ReplayBuffer(obs_dim=PAPER_OBS_DIM, act_dim=PAPER_ACT_DIM)
    started, episodes, evals, returns = time.monotonic(), 0, [], []
    rng_seed = seed * 1_000_000 + 70_000

    def evaluation() -> None:
        per_angle = {}
        for angle in EVAL_ANGLES:
            wins = 0
            for i in range(eval_trials):
                obs, _ = env.reset(seed=10_000 + i, options={"angle_deg": angle})
                done = False
                while not done:
                    obs, _, term, trunc, info = env.step(agent.act(obs))
                    done = term or trunc
                wins += info["success"]
            per_angle[f"{angle:g}"] = wins / eval_trials
        evals.append({"episode": episodes, "seconds": time.monotonic() - started, "per_angle": per_angle,
                      "mean_success": float(np.mean(list(per_angle.values())))})
        report({"phase": "eval", **evals[-1]})

    evaluation()
    while time.monotonic() - started < seconds:
        obs, _ = env.reset(seed=rng_seed + episodes)
        seen, done, total = [], False, 0.0
        while not done:
            a = agent.act(obs, explore=True)
            nxt, r, term, trunc, info = env.step(a)
            buffer.add(obs, a, r, nxt, float(term))
            seen.append(obs)
            total += r
            obs, done = nxt, term or trunc
        agent.norm.update(np.array(seen))  # from scratch: no cloned actor to keep the inputs of
        if buffer.size >= agent.cfg.batch:
            for _ in range(len(seen)):
                agent.update(buffer)
        episodes += 1
        returns.append({"episode": episodes, "return": total, "success": bool(info["success"])})
        report({"phase": "ddpg", "episode": episodes, "return": total, "success": bool(info["success"])})
        if episodes % eval_every == 0:
            evaluation()
    evaluation()
    return {"evals": evals, "returns": returns, "episodes": episodes, "seconds": time.monotonic() - started}


def plot_against(ours: dict, paper: dict, path: Path) -> Path:
    """Mean evaluation success against training time: the engineered policy's history (its
    cloned start as a dashed line) beside the paper's formulation."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    for label, run in ours.items():
        pts = [(e["seconds"] / 60, e["mean_success"]) for e in run if "seconds" in e]
        if pts:
            ax.plot(*zip(*pts), marker="o", ms=3, label=f"engineered, DDPG phase ({label})")
            ax.axhline(run[0]["mean_success"], ls="--", lw=0.8, color=ax.lines[-1].get_color())
    for label, run in paper.items():
        ax.plot([e["seconds"] / 60 for e in run], [e["mean_success"] for e in run], marker="s", ms=3,
                label=f"paper's formulation, from scratch ({label})")
    ax.set_xlabel("training time (min, 2 cores)")
    ax.set_ylabel("evaluation success (mean of 30–60°)")
    ax.set_ylim(-0.05, 1.05)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
