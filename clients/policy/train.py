"""Training the grasp policy (``hycosim train``): demonstrations, behaviour cloning, then DDPG.

Checkpoints (``last.pt``, ``best.pt``) hold the weights, optimiser states, normalisation
statistics, the training config and its hash, episodes done and metrics; a run resumes
from ``last.pt``. At the end ``learning_curve.png`` shows episode return and evaluation
success per release angle.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from clients.policy.ddpg import DDPG, CheckpointError, DDPGConfig, ReplayBuffer
from clients.policy.env import GraspEnv

EVAL_ANGLES = (30.0, 40.0, 50.0, 60.0)
PRECISE_MM = 3.0  # the trials' target for the grasp distance error


@dataclass
class TrainConfig:
    demo_episodes: int = 100
    bc_steps: int = 5000
    dagger_rounds: int = 3      # the cloned policy drives, the reference labels what it sees
    dagger_episodes: int = 40
    critic_warmup_steps: int = 5000
    episodes: int = 200
    eval_every: int = 20
    eval_trials: int = 10
    seed: int = 0
    ddpg: DDPGConfig = field(default_factory=DDPGConfig)

    def digest(self) -> str:
        return hashlib.sha256(json.dumps(asdict(self), sort_keys=True).encode()).hexdigest()[:16]


def evaluate(agent: DDPG | None, env: GraspEnv, trials: int, seed: int = 10_000,
             expert: bool = False) -> dict[str, dict[str, float]]:
    """Success rate, precise-grasp rate (within ``PRECISE_MM`` of the grasp point), mean time
    and mean final distance per release angle (deterministic policy)."""
    results = {}
    for angle in EVAL_ANGLES:
        wins, precise, times, dists = 0, 0, [], []
        for i in range(trials):
            obs, _ = env.reset(seed=seed + i, options={"angle_deg": angle})
            done = False
            while not done:
                action = env.expert_action() if expert else agent.act(obs)
                obs, _, term, trunc, info = env.step(action)
                done = term or trunc
            wins += info["success"]
            precise += info["success"] and 1000 * info["distance"] <= PRECISE_MM
            times.append(info["time"])
            dists.append(info["distance"])
        results[f"{angle:g}"] = {"success": wins / trials, "precise": precise / trials,
                                 "time_s": float(np.mean(times)), "distance_mm": 1000 * float(np.mean(dists))}
    return results


def _episode(env: GraspEnv, act: Callable[[np.ndarray], np.ndarray], seed: int, buffer: ReplayBuffer | None,
             demo: bool = False, norm=None) -> tuple[float, bool, list]:
    obs, _ = env.reset(seed=seed)
    total, done, seen = 0.0, False, []
    while not done:
        a = act(obs)
        nxt, r, term, trunc, info = env.step(a)
        if buffer is not None:
            buffer.add(obs, a, r, nxt, float(term), demo)
        seen.append((obs, a))
        total += r
        obs, done = nxt, term or trunc
    return total, bool(info["success"]), seen


def _labelled_episode(env: GraspEnv, agent: DDPG, seed: int) -> list:
    """One episode driven by the agent; each observation paired with the reference's action."""
    obs, _ = env.reset(seed=seed)
    seen, done = [], False
    while not done:
        seen.append((obs, env.expert_action()))
        obs, _, term, trunc, _ = env.step(agent.act(obs))
        done = term or trunc
    return seen


def train(out: Path, config: TrainConfig, progress: Callable[[dict], None] | None = None) -> dict:
    """Train into ``out``; resume from ``out/last.pt`` when it exists. Returns the final metrics."""
    out.mkdir(parents=True, exist_ok=True)
    env = GraspEnv()
    agent = DDPG(config.ddpg)
    buffer = ReplayBuffer()
    history: dict = {"returns": [], "evals": []}
    episodes_done, started = 0, time.monotonic()
    last = out / "last.pt"
    if last.exists():
        afresh = "remove it to start afresh, or use another output folder"
        try:
            state = torch.load(last, map_location="cpu", weights_only=False)
        except Exception as exc:  # torch raises pickle, zip and runtime errors alike for a damaged file
            raise CheckpointError(f"{last} is not a readable checkpoint ({exc}): {afresh}") from None
        if not isinstance(state, dict) or "history" not in state or "episodes" not in state:
            raise CheckpointError(f"{last} is not a training checkpoint of hycosim: {afresh}")
        if state.get("config_hash") != config.digest():
            raise ValueError(f"{last} was trained with another config (hash {state.get('config_hash')}); "
                             "use another output folder")
        try:
            agent.load_state(state)
        except (RuntimeError, KeyError, ValueError) as exc:
            raise CheckpointError(f"{last} does not fit the networks ({exc}): {afresh}") from None
        history = state["history"]
        episodes_done = state["episodes"]
    resumed = last.exists()
    report = progress or (lambda _: None)
    # Demonstrations (also on resume: the buffer is not checkpointed).
    demo_obs, demo_act = [], []
    for i in range(config.demo_episodes):
        _, _, seen = _episode(env, lambda _o: env.expert_action(), config.seed * 100_000 + i, buffer, demo=True)
        for o, a in seen:
            demo_obs.append(o)
            demo_act.append(a)
        report({"phase": "demonstrations", "done": i + 1, "total": config.demo_episodes})
    demo_obs_arr, demo_act_arr = np.array(demo_obs), np.array(demo_act)
    if not resumed:
        agent.norm.update(demo_obs_arr)
        bc = agent.pretrain_actor(demo_obs_arr, demo_act_arr, config.bc_steps)
        for r in range(config.dagger_rounds):
            # DAgger: states the cloned policy reaches, labelled with the reference's choice,
            # so that cloning is exact where the policy actually goes, not only on the demos.
            for i in range(config.dagger_episodes):
                seen = _labelled_episode(env, agent, config.seed * 100_000 + 10_000 * (r + 1) + i)
                demo_obs.extend(o for o, _ in seen)
                demo_act.extend(a for _, a in seen)
                report({"phase": "dagger", "done": r * config.dagger_episodes + i + 1,
                        "total": config.dagger_rounds * config.dagger_episodes})
            demo_obs_arr, demo_act_arr = np.array(demo_obs), np.array(demo_act)
            bc = agent.pretrain_actor(demo_obs_arr, demo_act_arr, config.bc_steps)
        for _ in range(config.critic_warmup_steps):
            agent.update(buffer, train_actor=False)
        ev = evaluate(agent, env, config.eval_trials)
        mean = float(np.mean([v["success"] for v in ev.values()]))
        history["evals"].append({"episode": 0, "per_angle": ev, "mean_success": mean})
        pretrained = agent.state(config_hash=config.digest(), episodes=0, history=history, metrics=ev,
                                 trained_s=time.monotonic() - started, train_config=asdict(config))
        _save(pretrained, out / "best.pt")
        _save(pretrained, last)  # a resume goes on from here, without cloning again
        report({"phase": "pretrained", "bc_mse": bc, "per_angle": ev, "mean_success": mean})
    best = max((_score(e) for e in history["evals"]), default=(-1.0, -1.0, -float("inf")))
    rng_seed = config.seed * 1_000_000 + 50_000
    for ep in range(episodes_done, config.episodes):
        ret, success, seen = _episode(env, lambda o: agent.act(o, explore=True), rng_seed + ep, buffer)
        agent.norm.update(np.array([o for o, _ in seen]))
        for _ in range(len(seen)):
            agent.update(buffer)
        history["returns"].append({"episode": ep + 1, "return": ret, "success": success})
        report({"phase": "ddpg", "episode": ep + 1, "total": config.episodes, "return": ret, "success": success})
        if (ep + 1) % config.eval_every == 0 or ep + 1 == config.episodes:
            ev = evaluate(agent, env, config.eval_trials)
            mean = float(np.mean([v["success"] for v in ev.values()]))
            history["evals"].append({"episode": ep + 1, "per_angle": ev, "mean_success": mean})
            report({"phase": "eval", "episode": ep + 1, "per_angle": ev, "mean_success": mean})
            extra = dict(config_hash=config.digest(), episodes=ep + 1, history=history,
                         trained_s=time.monotonic() - started, metrics=ev, train_config=asdict(config))
            score = _score(history["evals"][-1])
            if score >= best:
                best = score
                _save(agent.state(**extra), out / "best.pt")
            _save(agent.state(**extra), last)
    plot_learning_curve(history, out / "learning_curve.png")
    return {"best_mean_success": best[1], "best_mean_precise": best[0], "evals": history["evals"], "trained_s": time.monotonic() - started}


def _save(state: dict, path: Path) -> None:
    # Written beside and renamed over: a Ctrl-C or a full disk mid-write leaves the last
    # complete checkpoint, never a torn one.
    tmp = path.with_name(path.name + ".tmp")
    torch.save(state, tmp)
    tmp.replace(path)


def _score(evaluation: dict) -> tuple[float, float, float]:
    """Best checkpoint: the most grasps within PRECISE_MM (the jaws close on the rod anywhere
    between them, but the trials measure the offset), then the most grasps, then the closest."""
    per_angle = list(evaluation["per_angle"].values())
    return (float(np.mean([v.get("precise", 0.0) for v in per_angle])), evaluation["mean_success"],
            -float(np.mean([v["distance_mm"] for v in per_angle])))


def plot_learning_curve(history: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    if history["returns"]:
        eps = [r["episode"] for r in history["returns"]]
        rets = np.array([r["return"] for r in history["returns"]])
        a1.plot(eps, rets, color="0.7", lw=0.8, label="episode return")
        k = max(1, len(rets) // 20)
        a1.plot(eps[k - 1:], np.convolve(rets, np.ones(k) / k, mode="valid"), color="tab:blue", label=f"mean of {k}")
        a1.legend(fontsize=8)
    a1.set_ylabel("return (Eq. 6)")
    for angle in EVAL_ANGLES:
        pts = [(e["episode"], e["per_angle"][f"{angle:g}"]["success"]) for e in history["evals"]]
        if pts:
            a2.plot(*zip(*pts), marker="o", label=f"{angle:g}°")
    a2.set_ylabel("evaluation success")
    a2.set_xlabel("DDPG episode")
    a2.set_ylim(-0.05, 1.05)
    a2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
