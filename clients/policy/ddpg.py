"""DDPG in torch: actor and critic, target networks with soft updates, a replay buffer,
Gaussian exploration noise, running observation normalisation, seeding.

Learning is bootstrapped from demonstrations (DDPGfD, Vecerik et al. 2017): episodes of the
scripted reference controller seed the replay buffer, the actor is pretrained to imitate
them, and during DDPG a behaviour-cloning term pulls the actor towards demonstrated actions
only where the critic rates them higher than its own (the Q-filter of Nair et al. 2018).
"""

from __future__ import annotations

import copy
import random
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import nn

from clients.policy.features import ACT_DIM, OBS_DIM, RESIDUAL_DEG

CHECKPOINT_VERSION = 1


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


class RunningNorm:
    """Running mean and variance of observations (Welford); clipped standard scores."""

    def __init__(self, dim: int, clip: float = 5.0):
        self.mean = np.zeros(dim)
        self.var = np.ones(dim)
        self.count = 1e-4
        self.clip = clip

    def update(self, x: np.ndarray) -> None:
        x = np.atleast_2d(x)
        b_mean, b_var, n = x.mean(0), x.var(0), len(x)
        delta = b_mean - self.mean
        total = self.count + n
        self.mean = self.mean + delta * n / total
        self.var = (self.var * self.count + b_var * n + delta ** 2 * self.count * n / total) / total
        self.count = total

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return np.clip((x - self.mean) / np.sqrt(self.var + 1e-8), -self.clip, self.clip).astype(np.float32)

    def state(self) -> dict:
        return {"mean": self.mean.tolist(), "var": self.var.tolist(), "count": self.count}

    @staticmethod
    def from_state(state: dict) -> "RunningNorm":
        n = RunningNorm(len(state["mean"]))
        n.mean, n.var, n.count = np.array(state["mean"]), np.array(state["var"]), state["count"]
        return n


def mlp(inp: int, out: int, hidden: int = 256, final: nn.Module | None = None) -> nn.Sequential:
    layers: list[nn.Module] = [nn.Linear(inp, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(),
                               nn.Linear(hidden, out)]
    if final is not None:
        layers.append(final)
    return nn.Sequential(*layers)


class ReplayBuffer:
    def __init__(self, capacity: int = 300_000):
        self.capacity = capacity
        self.obs = np.zeros((capacity, OBS_DIM), np.float32)
        self.act = np.zeros((capacity, ACT_DIM), np.float32)
        self.rew = np.zeros(capacity, np.float32)
        self.nxt = np.zeros((capacity, OBS_DIM), np.float32)
        self.done = np.zeros(capacity, np.float32)
        self.demo = np.zeros(capacity, bool)
        self.size = 0
        self.pos = 0
        self.n_demo = 0

    def add(self, o, a, r, o2, d, demo: bool = False) -> None:
        i = self.pos
        if demo:  # demonstrations stay: they fill the start of the buffer, which is never overwritten
            i = self.n_demo
            self.n_demo += 1
            self.pos = max(self.pos, self.n_demo)
        self.obs[i], self.act[i], self.rew[i], self.nxt[i], self.done[i], self.demo[i] = o, a, r, o2, d, demo
        self.size = min(self.capacity, max(self.size, i + 1))
        if not demo:
            self.pos = self.pos + 1 if self.pos + 1 < self.capacity else self.n_demo

    def sample(self, n: int, rng: np.random.Generator):
        idx = rng.integers(0, self.size, n)
        return self.obs[idx], self.act[idx], self.rew[idx], self.nxt[idx], self.done[idx], self.demo[idx]


@dataclass
class DDPGConfig:
    gamma: float = 0.98
    tau: float = 0.005
    actor_lr: float = 1e-5
    critic_lr: float = 1e-3
    batch: int = 256
    noise: float = 0.05
    bc_weight: float = 5.0
    bc_lr: float = 1e-3  # behaviour cloning fits the demonstrations; DDPG's actor_lr is for fine changes
    hidden: int = 256
    seed: int = 0
    extra: dict = field(default_factory=dict)


class DDPG:
    def __init__(self, config: DDPGConfig | None = None):
        self.cfg = config or DDPGConfig()
        seed_everything(self.cfg.seed)
        torch.set_num_threads(1)
        self.actor = mlp(OBS_DIM, ACT_DIM, self.cfg.hidden, nn.Tanh())
        self.critic = mlp(OBS_DIM + ACT_DIM, 1, self.cfg.hidden)
        self.actor_target = copy.deepcopy(self.actor)
        self.critic_target = copy.deepcopy(self.critic)
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=self.cfg.actor_lr)
        self.critic_opt = torch.optim.Adam(self.critic.parameters(), lr=self.cfg.critic_lr)
        self.norm = RunningNorm(OBS_DIM)
        self.rng = np.random.default_rng(self.cfg.seed)

    # --- acting ----------------------------------------------------------------------

    @torch.no_grad()
    def act(self, obs: np.ndarray, explore: bool = False) -> np.ndarray:
        a = self.actor(torch.from_numpy(self.norm(obs))[None]).numpy()[0]
        if explore:
            a = a + self.rng.normal(0.0, self.cfg.noise, a.shape)
        return np.clip(a, -1.0, 1.0).astype(np.float32)

    # --- learning --------------------------------------------------------------------

    def _batch(self, buffer: ReplayBuffer):
        o, a, r, o2, d, demo = buffer.sample(self.cfg.batch, self.rng)
        t = lambda x: torch.from_numpy(np.asarray(x, np.float32))  # noqa: E731
        return t(self.norm(o)), t(a), t(r)[:, None], t(self.norm(o2)), t(d)[:, None], torch.from_numpy(demo)

    def pretrain_actor(self, obs: np.ndarray, actions: np.ndarray, steps: int) -> float:
        """Behaviour cloning on demonstrations; returns the final mean squared error."""
        x, y = torch.from_numpy(self.norm(obs)), torch.from_numpy(actions.astype(np.float32))
        loss = torch.tensor(0.0)
        opt = torch.optim.Adam(self.actor.parameters(), lr=self.cfg.bc_lr)
        # Decay to a tenth: millimetre grasps need the residual outputs fitted closely.
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, max(steps, 1), eta_min=self.cfg.bc_lr / 10)
        for _ in range(steps):
            idx = torch.from_numpy(self.rng.integers(0, len(x), min(self.cfg.batch, len(x))))
            loss = ((self.actor(x[idx]) - y[idx]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
        self.actor_target.load_state_dict(self.actor.state_dict())
        return float(loss.detach())

    def update(self, buffer: ReplayBuffer, train_actor: bool = True) -> dict[str, float]:
        o, a, r, o2, d, demo = self._batch(buffer)
        with torch.no_grad():
            target = r + self.cfg.gamma * (1 - d) * self.critic_target(torch.cat([o2, self.actor_target(o2)], 1))
        q = self.critic(torch.cat([o, a], 1))
        critic_loss = ((q - target) ** 2).mean()
        self.critic_opt.zero_grad()
        critic_loss.backward()
        self.critic_opt.step()
        stats = {"critic_loss": float(critic_loss.detach())}
        if train_actor:
            pi = self.actor(o)
            q_pi = self.critic(torch.cat([o, pi], 1))
            actor_loss = -q_pi.mean()
            if demo.any() and self.cfg.bc_weight > 0:
                with torch.no_grad():
                    better = (q > q_pi).squeeze(1) & demo  # Q-filter: imitate only where the demo looks better
                if better.any():
                    actor_loss = actor_loss + self.cfg.bc_weight * ((pi[better] - a[better]) ** 2).sum(1).mean()
            self.actor_opt.zero_grad()
            actor_loss.backward()
            self.actor_opt.step()
            stats["actor_loss"] = float(actor_loss.detach())
        with torch.no_grad():
            for net, tgt in ((self.actor, self.actor_target), (self.critic, self.critic_target)):
                for p, tp in zip(net.parameters(), tgt.parameters()):
                    tp.mul_(1 - self.cfg.tau).add_(self.cfg.tau * p)
        return stats

    # --- checkpoints -----------------------------------------------------------------

    def state(self, **extra) -> dict:
        return {"version": CHECKPOINT_VERSION, "obs_dim": OBS_DIM, "act_dim": ACT_DIM, "hidden": self.cfg.hidden,
                "residual_deg": RESIDUAL_DEG,
                "actor": self.actor.state_dict(), "critic": self.critic.state_dict(),
                "actor_target": self.actor_target.state_dict(), "critic_target": self.critic_target.state_dict(),
                "actor_opt": self.actor_opt.state_dict(), "critic_opt": self.critic_opt.state_dict(),
                "norm": self.norm.state(), "config": self.cfg.__dict__, **extra}

    def load_state(self, state: dict, optimisers: bool = True) -> None:
        self.actor.load_state_dict(state["actor"])
        self.critic.load_state_dict(state["critic"])
        self.actor_target.load_state_dict(state.get("actor_target", state["actor"]))
        self.critic_target.load_state_dict(state.get("critic_target", state["critic"]))
        if optimisers and "actor_opt" in state:
            self.actor_opt.load_state_dict(state["actor_opt"])
            self.critic_opt.load_state_dict(state["critic_opt"])
        self.norm = RunningNorm.from_state(state["norm"])


def strip_checkpoint(src, dst) -> None:
    """A small copy of a checkpoint for acting and evaluation: no optimiser or target networks."""
    state = torch.load(src, map_location="cpu", weights_only=False)
    keep = ("version", "obs_dim", "act_dim", "hidden", "residual_deg", "actor", "critic", "norm", "config", "config_hash",
            "episodes", "metrics", "trained_s", "train_config")
    torch.save({k: state[k] for k in keep if k in state}, dst)


class CheckpointError(RuntimeError):
    """A checkpoint that is missing, unreadable or made for another observation/action layout."""


def load_policy(path, hidden: int | None = None) -> DDPG:
    """A DDPG agent from a checkpoint file, for acting; CheckpointError names the file."""
    from pathlib import Path

    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint {path} does not exist (train one with `hycosim train`)")
    try:
        state = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as exc:
        raise CheckpointError(f"checkpoint {path} is not readable: {exc}") from None
    if not isinstance(state, dict) or state.get("version") != CHECKPOINT_VERSION:
        raise CheckpointError(f"checkpoint {path} is not a hycosim DDPG checkpoint of version {CHECKPOINT_VERSION}")
    if state.get("obs_dim") != OBS_DIM or state.get("act_dim") != ACT_DIM:
        raise CheckpointError(f"checkpoint {path} expects {state.get('obs_dim')} observations and "
                              f"{state.get('act_dim')} actions; this policy has {OBS_DIM} and {ACT_DIM}")
    if state.get("residual_deg", 15.0) != RESIDUAL_DEG:
        raise CheckpointError(f"checkpoint {path} was trained for joint corrections of ±{state.get('residual_deg', 15.0)}°; "
                              f"this policy applies ±{RESIDUAL_DEG}° (retrain with `hycosim train`)")
    agent = DDPG(DDPGConfig(hidden=state.get("hidden", hidden or 256)))
    try:
        agent.load_state(state, optimisers=False)
    except (RuntimeError, KeyError) as exc:
        raise CheckpointError(f"checkpoint {path} does not fit the networks: {exc}") from None
    agent.meta = {k: v for k, v in state.items() if k in ("metrics", "config_hash", "episodes", "trained_s")}
    return agent
