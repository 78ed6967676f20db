"""Training the grasp policy (``hycosim train``): demonstrations, behaviour cloning, then DDPG.

Checkpoints (``last.pt``, ``best.pt``) hold the weights, optimiser states, normalisation
statistics, the training config and its hash, episodes done and metrics; a run resumes
from ``last.pt``. Each evaluation also leaves a small snapshot (``snapshots/``); at the end
the leading ones and the last are compared on fresh episodes and the best becomes
``best.pt`` (10 evaluation episodes per angle only shortlist). ``learning_curve.png``
shows episode return and evaluation success per release angle.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from hycosim.scenario.policy.ddpg import DDPG, CheckpointError, DDPGConfig, ReplayBuffer, acting_part
from hycosim.scenario.policy.env import GRASP_TOLERANCE, GraspEnv
from hycosim.scenario.policy.history import ResumeError, check_resumable
from hycosim.core.folders import make_folder
from hycosim.core.lifetime import end_with

EVAL_ANGLES = (30.0, 40.0, 50.0, 60.0)
PRECISE_MM = 1000 * GRASP_TOLERANCE  # a precise grasp, as reported and as the reward pays it
SELECTION_SEED = 20_000  # episodes the final choice of checkpoint is made on (evaluations use 10_000 on)


@dataclass
class TrainConfig:
    """A training run's settings: demonstrations, behaviour cloning and DAgger rounds, the critics'
    warm-up, the DDPG episodes and their evaluation, and DDPG's own settings."""

    demo_episodes: int = 100
    bc_steps: int = 5000
    dagger_rounds: int = 3      # the cloned policy drives, the reference labels what it sees
    dagger_episodes: int = 40
    critic_warmup_steps: int = 5000
    cloned_episodes: int = 40   # the cloned policy's own rollouts, exploring, for the critics before the actor moves
    episodes: int = 200
    eval_every: int = 20
    eval_trials: int = 10
    focus: float = 0.0          # share of DDPG episodes released in a band of angles drawn by how often it fails
    select_trials: int = 50     # per angle, on fresh episodes, to choose best.pt among the leading checkpoints
    seed: int = 0
    ddpg: DDPGConfig = field(default_factory=DDPGConfig)

    def digest(self) -> str:
        """A short hash of the settings: a resume takes only a ``last.pt`` written with the same."""
        return hashlib.sha256(json.dumps(asdict(self), sort_keys=True).encode()).hexdigest()[:16]


def evaluate(agent: DDPG | None, env: GraspEnv, trials: int, seed: int = 10_000,
             expert: bool = False) -> dict[str, dict[str, float]]:
    """Per release angle (deterministic policy): success rate, precise-grasp rate (within
    ``PRECISE_MM`` of the grasp point), collisions, mean episode time, mean time to a grasp,
    mean final distance, and the episodes counted."""
    results = {}
    for angle in EVAL_ANGLES:
        wins, precise, collisions, times, grasp_times, dists = 0, 0, 0, [], [], []
        for i in range(trials):
            obs, _ = env.reset(seed=seed + i, options={"angle_deg": angle})
            done = False
            while not done:
                action = env.expert_action() if expert else agent.act(obs)
                obs, _, term, trunc, info = env.step(action)
                done = term or trunc
            wins += info["success"]
            precise += info["success"] and 1000 * info["distance"] <= PRECISE_MM
            collisions += info["collision"]
            times.append(info["time"])
            if info["success"]:
                grasp_times.append(info["time"])
            dists.append(info["distance"])
        results[f"{angle:g}"] = {"success": wins / trials, "precise": precise / trials,
                                 "collision": collisions / trials, "episodes": trials,
                                 "time_s": float(np.mean(times)),
                                 "grasp_time_s": float(np.mean(grasp_times)) if grasp_times else None,
                                 "distance_mm": 1000 * float(np.mean(dists))}
    return results


def _evaluate_part(path: str, angle: float, seeds: tuple[int, int]) -> list[dict]:
    from hycosim.scenario.policy.ddpg import load_policy

    torch.set_num_threads(1)
    agent, env = load_policy(path), GraspEnv()
    outcomes = []
    for s in range(*seeds):
        obs, _ = env.reset(seed=s, options={"angle_deg": angle})
        done = False
        while not done:
            obs, _, term, trunc, info = env.step(agent.act(obs))
            done = term or trunc
        outcomes.append(info)
    return outcomes


def evaluate_checkpoint(path: Path, trials: int, workers: int = 1, seed: int = 10_000,
                        angles: tuple[float, ...] = EVAL_ANGLES) -> dict[str, dict]:
    """:func:`evaluate` of a checkpoint file, its episodes spread over ``workers`` processes,
    with each rate's 95 % Wilson interval: at 100 episodes per angle 90 % reads 83–94 %
    and 98 % reads 93–99 %, so the two are told apart."""
    from concurrent.futures import ProcessPoolExecutor

    chunk = max(1, -(-trials // max(1, workers)))
    parts = [(angle, (seed + i, seed + min(i + chunk, trials))) for angle in angles for i in range(0, trials, chunk)]
    with ProcessPoolExecutor(max_workers=workers, initializer=end_with, initargs=(os.getpid(),)) as pool:
        done = list(pool.map(_evaluate_part, [str(path)] * len(parts), [a for a, _ in parts], [s for _, s in parts]))
    results = {}
    for angle in angles:
        infos = [info for (a, _), chunk_infos in zip(parts, done) if a == angle for info in chunk_infos]
        n = len(infos)
        wins = sum(i["success"] for i in infos)
        precise = sum(i["success"] and 1000 * i["distance"] <= PRECISE_MM for i in infos)
        grasp_times = [i["time"] for i in infos if i["success"]]
        results[f"{angle:g}"] = {
            "episodes": n, "success": wins / n, "success_95": wilson(wins, n), "precise": precise / n,
            "precise_95": wilson(precise, n), "collision": sum(i["collision"] for i in infos) / n,
            "time_s": float(np.mean([i["time"] for i in infos])),
            "grasp_time_s": float(np.mean(grasp_times)) if grasp_times else None,
            "distance_mm": 1000 * float(np.mean([i["distance"] for i in infos])),
            "grasp_distance_mm": 1000 * float(np.mean([i["distance"] for i in infos if i["success"]]))
            if grasp_times else None}
    return results


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The Wilson score interval of a rate k/n (sound near 0 and 1, where the normal one is not)."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (float(max(0.0, centre - half)), float(min(1.0, centre + half)))


def _episode(env: GraspEnv, act: Callable[[np.ndarray], np.ndarray], seed: int, buffer: ReplayBuffer | None,
             demo: bool = False, rewards: list | None = None, options: dict | None = None) -> tuple[float, bool, list]:
    obs, _ = env.reset(seed=seed, options=options)
    total, done, seen, steps = 0.0, False, [], []
    while not done:
        a = act(obs)
        nxt, r, term, trunc, info = env.step(a)
        steps.append((obs, a, r, nxt, float(term)))
        seen.append((obs, a))
        if rewards is not None:
            rewards.append(r)
        total += r
        obs, done = nxt, term or trunc
    if buffer is not None:
        buffer.add_episode(steps, demo)
    return total, bool(info["success"]), seen


BANDS = ((30.0, 40.0), (40.0, 50.0), (50.0, 60.0))


def focus_options(rng: np.random.Generator, recent: list[dict], share: float) -> dict | None:
    """Where the next DDPG episode releases the rod: with probability ``share``, in a band of
    angles drawn by the failure rate of the recent episodes released in it (Laplace-smoothed,
    so a band seldom seen still gets its turn); otherwise as the environment draws it."""
    if share <= 0 or rng.random() >= share:
        return None
    weights = []
    for lo, hi in BANDS:
        # An episode without its angle (a record from before angles were kept) is in no band.
        outcomes = [r["success"] for r in recent if r.get("angle") is not None and lo <= r["angle"] <= hi]
        weights.append((len(outcomes) - sum(outcomes) + 1) / (len(outcomes) + 2))
    band = BANDS[int(rng.choice(len(BANDS), p=np.array(weights) / sum(weights)))]
    return {"angle_deg": float(rng.uniform(*band))}


def critic_error(agent: DDPG, seen: list, rewards: list, ends: list[int]) -> dict[str, float]:
    """How well the critics know the value of the actions taken in some episodes: Q(s, a)
    against the discounted return that followed (Monte Carlo), mean absolute and relative.
    The return of a truncated episode misses what the critics bootstrap; episodes here end
    on a grasp, a collision or the step limit's penalty, so the difference is small."""
    returns = np.zeros(len(rewards))
    start = 0
    for end in ends:
        g = 0.0
        for i in range(end - 1, start - 1, -1):
            g = rewards[i] + agent.cfg.gamma * g
            returns[i] = g
        start = end
    obs = torch.from_numpy(agent.norm(np.array([o for o, _ in seen])))
    act = torch.from_numpy(np.array([a for _, a in seen], dtype=np.float32))
    with torch.no_grad():
        q = agent.q(obs, act).squeeze(1).numpy()
    err = np.abs(q - returns)
    return {"mae": float(err.mean()), "relative": float(err.mean() / max(np.abs(returns).mean(), 1e-9)),
            "q_mean": float(q.mean()), "return_mean": float(returns.mean())}


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
    make_folder(out)
    env = GraspEnv()
    agent = DDPG(config.ddpg)
    buffer = ReplayBuffer(n_step=config.ddpg.n_step, gamma=config.ddpg.gamma)
    history: dict = {"returns": [], "evals": []}
    episodes_done, started = 0, time.monotonic()
    last = out / "last.pt"
    if last.exists():
        afresh = "remove it to start afresh, or use another output folder"
        try:
            state = torch.load(last, map_location="cpu", weights_only=True)
        except Exception as exc:  # torch raises pickle, zip and runtime errors alike for a damaged file
            raise CheckpointError(f"{last} is not a readable checkpoint ({exc}): {afresh}") from None
        if not isinstance(state, dict) or "history" not in state or "episodes" not in state:
            raise CheckpointError(f"{last} is not a training checkpoint of hycosim: {afresh}")
        if state.get("config_hash") != config.digest():
            raise ValueError(f"{last} was trained with another config (hash {state.get('config_hash')}); "
                             "use another output folder")
        try:
            agent.load_state(state)
        except (RuntimeError, KeyError, TypeError, ValueError) as exc:
            raise CheckpointError(f"{last} does not fit the networks ({exc}): {afresh}") from None
        try:
            history, episodes_done, trained_s = check_resumable(state, EVAL_ANGLES)
        except ResumeError as exc:
            raise CheckpointError(f"{last}: {exc}: {afresh}") from None
        started -= trained_s  # training time counts across resumes
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
    if resumed and agent.anchor is not None:
        # The cloned policy's exploring rollouts were in the buffer too: rebuilt the same way.
        for i in range(config.cloned_episodes):
            agent.new_episode()
            _episode(env, lambda o: agent.act(o, explore=True, actor=agent.anchor), config.seed * 100_000 + 95_000 + i,
                     buffer)
            report({"phase": "rollouts", "done": i + 1, "total": config.cloned_episodes})
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
        # The critics first learn from the demonstrations alone (as before this phase had
        # rollouts), then from the cloned policy's own exploring rollouts too: the error on
        # those rollouts, measured after each, is what the actor's gradient is made of.
        agent.freeze_anchor()
        for _ in range(config.critic_warmup_steps):
            agent.update(buffer, train_actor=False)
        held, rewards, ends = [], [], []  # rollouts kept out of the buffer, to measure the critics on
        held_out = max(1, config.cloned_episodes // 4) if config.cloned_episodes else 0
        for i in range(held_out + config.cloned_episodes):
            agent.new_episode()
            keep = i < held_out
            _, _, seen = _episode(env, lambda o: agent.act(o, explore=True), config.seed * 100_000 + 90_000 + i,
                                  None if keep else buffer, rewards=rewards if keep else None)
            if keep:
                held.extend(seen)
                ends.append(len(rewards))
            report({"phase": "rollouts", "done": i + 1, "total": held_out + config.cloned_episodes})
        if held:
            history["critic_error"] = {"demonstrations_only": critic_error(agent, held, rewards, ends)}
            for _ in range(config.critic_warmup_steps):
                agent.update(buffer, train_actor=False)
            history["critic_error"]["with_rollouts"] = critic_error(agent, held, rewards, ends)
        ev = evaluate(agent, env, config.eval_trials)
        mean = float(np.mean([v["success"] for v in ev.values()]))
        history["evals"].append({"episode": 0, "per_angle": ev, "mean_success": mean,
                                 "seconds": time.monotonic() - started})
        pretrained = agent.state(config_hash=config.digest(), episodes=0, history=history, metrics=ev,
                                 trained_s=time.monotonic() - started, train_config=asdict(config))
        _save(pretrained, out / "best.pt")
        _save(pretrained, last)  # a resume goes on from here, without cloning again
        _snapshot(pretrained, out, 0)
        report({"phase": "pretrained", "bc_mse": bc, "per_angle": ev, "mean_success": mean})
    best = max((_score(e) for e in history["evals"]), default=(-1.0, -1.0, -float("inf")))
    rng_seed = config.seed * 1_000_000 + 50_000
    for ep in range(episodes_done, config.episodes):
        agent.new_episode()
        where = focus_options(np.random.default_rng(rng_seed + ep), history["returns"][-50:], config.focus)
        ret, success, seen = _episode(env, lambda o: agent.act(o, explore=True), rng_seed + ep, buffer, options=where)
        # The normalisation stays that of the cloned policy: moving it would move the cloned
        # actor the DDPG phase is anchored to (its inputs are the normalised observations).
        for _ in range(len(seen)):
            agent.update(buffer)
        history["returns"].append({"episode": ep + 1, "return": ret, "success": success, "angle": env.amplitude_deg})
        report({"phase": "ddpg", "episode": ep + 1, "total": config.episodes, "return": ret, "success": success})
        if (ep + 1) % config.eval_every == 0 or ep + 1 == config.episodes:
            ev = evaluate(agent, env, config.eval_trials)
            mean = float(np.mean([v["success"] for v in ev.values()]))
            history["evals"].append({"episode": ep + 1, "per_angle": ev, "mean_success": mean,
                                     "seconds": time.monotonic() - started})
            report({"phase": "eval", "episode": ep + 1, "per_angle": ev, "mean_success": mean})
            extra = dict(config_hash=config.digest(), episodes=ep + 1, history=history,
                         trained_s=time.monotonic() - started, metrics=ev, train_config=asdict(config),
                         start_metrics=history["evals"][0]["per_angle"])
            score = _score(history["evals"][-1])
            if score >= best:
                best = score
                _save(agent.state(**extra), out / "best.pt")
            _save(agent.state(**extra), last)
            _snapshot(agent.state(**extra), out, ep + 1)
    if config.select_trials > 0 and history["evals"]:
        history["selection"] = select_checkpoint(out, history["evals"], config.select_trials, report)
        _save({**torch.load(last, map_location="cpu", weights_only=True), "history": history}, last)
    plot_learning_curve(history, out / "learning_curve.png")
    chosen = history.get("selection", {}).get("episode")
    return {"best_mean_success": best[1], "best_mean_precise": best[0], "evals": history["evals"],
            "trained_s": time.monotonic() - started, "critic_error": history.get("critic_error"),
            "selected_episode": chosen}


def _snapshot(state: dict, out: Path, episode: int) -> None:
    """The policy as it stood at an evaluation (no optimiser or targets), for the final choice."""
    (out / "snapshots").mkdir(exist_ok=True)
    _save(acting_part(state), out / "snapshots" / f"episode-{episode:05d}.pt")


def select_checkpoint(out: Path, evals: list[dict], trials: int, report: Callable[[dict], None],
                      leaders: int = 3) -> dict:
    """``best.pt``: of the leading checkpoints by the training's evaluations (10 episodes per
    angle cannot tell 90 % from 98 %) and the last, the one that scores best on ``trials``
    fresh episodes per angle, none of them the training's or the reported evaluation's."""
    import os

    ranked = sorted(evals, key=_score, reverse=True)[:leaders]
    episodes = sorted({e["episode"] for e in ranked} | {evals[-1]["episode"]})
    figures = {}
    for n, episode in enumerate(episodes):
        path = out / "snapshots" / f"episode-{episode:05d}.pt"
        if path.exists():
            figures[episode] = evaluate_checkpoint(path, trials, workers=os.cpu_count() or 1, seed=SELECTION_SEED)
        report({"phase": "select", "done": n + 1, "total": len(episodes)})
    if not figures:
        return {}
    scored = {ep: _score({"per_angle": f, "mean_success": float(np.mean([v["success"] for v in f.values()]))})
              for ep, f in figures.items()}
    chosen = max(scored, key=lambda ep: (scored[ep], ep))
    state = torch.load(out / "snapshots" / f"episode-{chosen:05d}.pt", map_location="cpu", weights_only=True)
    _save({**state, "selection": {"episode": chosen, "trials": trials, "per_angle": figures[chosen]}}, out / "best.pt")
    return {"episode": chosen, "trials": trials,
            "candidates": {str(ep): {"score": list(scored[ep]), "per_angle": figures[ep]} for ep in figures}}


def _save(state: dict, path: Path) -> None:
    # Written beside and renamed over: a Ctrl-C or a full disk mid-write leaves the last
    # complete checkpoint, never a torn one.
    tmp = path.with_name(path.name + ".tmp")
    torch.save(state, tmp)
    tmp.replace(path)


def _score(evaluation: dict) -> tuple[float, float, float]:
    """Best checkpoint: the most grasps within PRECISE_MM (the jaws close on the rod anywhere
    between them, but the trials measure the offset), then the most grasps, then the quickest
    episodes (what the reward's discount asks for, and the trials' execution time; among
    policies that all grasp within a millimetre the mean distance only told noise apart)."""
    per_angle = list(evaluation["per_angle"].values())
    return (float(np.mean([v.get("precise", 0.0) for v in per_angle])), evaluation["mean_success"],
            -float(np.mean([v["time_s"] for v in per_angle])))


def plot_learning_curve(history: dict, path: Path) -> Path:
    """Plot the training's returns and its evaluations' success per angle into ``path`` (PNG); returns
    ``path``."""
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
            line, = a2.plot(*zip(*pts), marker="o", label=f"{angle:g}°")
            if pts[0][0] == 0:  # the cloned start, for reference
                a2.axhline(pts[0][1], ls="--", lw=0.8, color=line.get_color())
    a2.set_ylabel("evaluation success (dashed: cloned start)")
    a2.set_xlabel("DDPG episode")
    a2.set_ylim(-0.05, 1.05)
    a2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
