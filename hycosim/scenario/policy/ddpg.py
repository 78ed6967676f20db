"""DDPG in torch: a deterministic actor, twin critics, target networks with soft updates, a
replay buffer, exploration noise, running observation normalisation, seeding.

Learning is bootstrapped from demonstrations (DDPGfD, Vecerik et al. 2017): episodes of the
scripted reference controller seed the replay buffer and stay in it, and the actor is
pretrained to imitate them. The DDPG phase then fine-tunes without forgetting:

* the critics are trained on the cloned policy's own rollouts before the actor moves, so
  that they rate its actions, not only the teacher's;
* twin critics, the smaller of their targets, target-policy smoothing and delayed actor
  updates (TD3, Fujimoto et al. 2018; still a deterministic policy gradient);
* the actor's objective is Q scaled by its mean magnitude (TD3+BC, Fujimoto and Gu 2021), so
  the reward's scale (+100 for a grasp) does not set the step size, plus a behaviour-cloning
  term towards the demonstrations, kept only where the critics rate them at least as high as
  the actor's own action (the Q-filter of Nair et al. 2018), and a strong pull of the joint
  corrections towards the cloned actor's: the critics' error on millimetre corrections is
  of the order of the returns (measured in ``train.critic_error``), so they are not trusted
  with them;
* the first action number is a choice between two turning points, a step function to the
  critics; its gradient is near zero on both sides, so it is trained towards whichever
  option the critics rate higher by a margin (as for the discrete part of a parameterised
  action, Hausknecht and Stone 2016), and explored with temporally correlated noise so that
  an exploring episode keeps a choice long enough to see where it leads;
* optionally (``n_step``), the critics also learn from n-step returns, as DDPGfD does; measured
  on this task it did not help (benchmarks/FINDINGS.md), so it is off by default.
"""

from __future__ import annotations

import copy
import math
import random
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import nn

from hycosim.scenario.policy.features import ACT_DIM, OBS_DIM, RESIDUAL_DEG

CHECKPOINT_VERSION = 1


def seed_everything(seed: int) -> None:
    """Seed Python's, NumPy's and torch's generators alike, so that a training run repeats."""
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
        """Fold a batch of observations (one per row) into the running mean and variance."""
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
        """The statistics as plain data, for a checkpoint (:meth:`from_state` reads them back)."""
        return {"mean": self.mean.tolist(), "var": self.var.tolist(), "count": self.count}

    @staticmethod
    def from_state(state: dict, dim: int) -> "RunningNorm":
        """The statistics :meth:`state` saved, for ``dim`` observations; ValueError if they are not."""
        if type(state) is not dict:
            raise ValueError("the observation statistics are not a map")
        mean, var, count = (np.asarray(state.get(k), dtype=float) for k in ("mean", "var", "count"))
        if mean.shape != (dim,) or var.shape != (dim,) or count.shape != ():
            raise ValueError(f"the observation statistics are not of {dim} observations")
        if not (np.isfinite(mean).all() and np.isfinite(var).all() and (var >= 0).all() and 0 < count < math.inf):
            raise ValueError("the observation statistics hold values that are no mean, variance or count")
        n = RunningNorm(dim)
        n.mean, n.var, n.count = mean, var, float(count)
        return n


def mlp(inp: int, out: int, hidden: int = 256, final: nn.Module | None = None) -> nn.Sequential:
    """A perceptron of two hidden ReLU layers of ``hidden`` units, from ``inp`` to ``out``, with
    ``final`` (an activation) after it where given."""
    layers: list[nn.Module] = [nn.Linear(inp, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(),
                               nn.Linear(hidden, out)]
    if final is not None:
        layers.append(final)
    return nn.Sequential(*layers)


class ReplayBuffer:
    """Transitions, each with its one-step and its n-step target inputs: the rewards of up to
    ``n_step`` steps summed with discount, the observation they lead to, whether the episode
    ended within them, and the discount left to bootstrap with (DDPGfD's n-step return)."""

    def __init__(self, capacity: int = 300_000, obs_dim: int = OBS_DIM, act_dim: int = ACT_DIM,
                 n_step: int = 1, gamma: float = 0.98):
        self.capacity = capacity
        self.n_step, self.gamma = n_step, gamma
        self.obs = np.zeros((capacity, obs_dim), np.float32)
        self.act = np.zeros((capacity, act_dim), np.float32)
        self.rew = np.zeros(capacity, np.float32)
        self.nxt = np.zeros((capacity, obs_dim), np.float32)
        self.done = np.zeros(capacity, np.float32)
        self.rew_n = np.zeros(capacity, np.float32)
        self.nxt_n = np.zeros((capacity, obs_dim), np.float32)
        self.done_n = np.zeros(capacity, np.float32)
        self.disc_n = np.zeros(capacity, np.float32)
        self.demo = np.zeros(capacity, bool)
        self.size = 0
        self.pos = 0
        self.n_demo = 0

    def add(self, o, a, r, o2, d, demo: bool = False, n_step: tuple | None = None) -> None:
        """One transition; ``n_step`` is (reward sum, observation, done, discount), or the
        one-step values when not given."""
        i = self.pos
        if demo:  # demonstrations stay: they fill the start of the buffer, which is never overwritten
            i = self.n_demo
            self.n_demo += 1
            self.pos = max(self.pos, self.n_demo)
        self.obs[i], self.act[i], self.rew[i], self.nxt[i], self.done[i], self.demo[i] = o, a, r, o2, d, demo
        self.rew_n[i], self.nxt_n[i], self.done_n[i], self.disc_n[i] = n_step or (r, o2, d, self.gamma)
        self.size = min(self.capacity, max(self.size, i + 1))
        if not demo:
            self.pos = self.pos + 1 if self.pos + 1 < self.capacity else self.n_demo

    def add_episode(self, steps: list[tuple], demo: bool = False) -> None:
        """An episode's transitions (o, a, r, o2, done) in order, each stored with the
        return of up to ``n_step`` steps from it; near the end the sum is shorter, and a
        truncated episode bootstraps from its last observation."""
        g = self.gamma
        for t, (o, a, r, o2, d) in enumerate(steps):
            window = steps[t:t + self.n_step]
            total = sum(g ** k * step[2] for k, step in enumerate(window))
            last = window[-1]
            self.add(o, a, r, o2, d, demo, (total, last[3], last[4], g ** len(window)))

    def sample(self, n: int, rng: np.random.Generator):
        """``n`` transitions drawn uniformly with ``rng``, as arrays: observations, actions, rewards,
        next observations, dones, demonstration flags, and the n-step reward sums, observations, dones
        and discounts."""
        idx = rng.integers(0, self.size, n)
        return (self.obs[idx], self.act[idx], self.rew[idx], self.nxt[idx], self.done[idx], self.demo[idx],
                self.rew_n[idx], self.nxt_n[idx], self.done_n[idx], self.disc_n[idx])


@dataclass
class DDPGConfig:
    """DDPG's settings: discount, soft-update rate, learning rates, batch size, exploration noise, TD3's
    smoothing and delay, the cloning terms' weights, the network size and the seed."""

    gamma: float = 0.98
    tau: float = 0.005
    actor_lr: float = 1e-5
    critic_lr: float = 1e-3
    batch: int = 256
    noise: float = 0.05          # Gaussian exploration on the joint corrections
    choice_noise: float = 0.6    # Ornstein-Uhlenbeck exploration on the turning-point choice
    choice_theta: float = 0.05   # its pull back per step: a deviation lasts ~20 steps
    # Q units the other turning point must gain before the actor switches: the critics' error
    # on held-out returns is ~25 (of ~44), and at 1.0 the phase traded 60° grasps for speed.
    choice_margin: float = 10.0
    choice: bool = True          # the first action number is the choice of turning point
    policy_noise: float = 0.1    # target-policy smoothing on the corrections (TD3)
    noise_clip: float = 0.2
    n_step: int = 1              # the critics also learn from n-step returns (DDPGfD) when above 1
    n_step_weight: float = 1.0
    policy_delay: int = 2
    alpha: float = 2.5           # TD3+BC: the weight of Q against the cloning terms
    bc_weight: float = 1.0
    anchor_weight: float = 50.0     # the corrections stay within ~0.03 of the cloned actor's (0.1°)
    bc_lr: float = 1e-3  # behaviour cloning fits the demonstrations; DDPG's actor_lr is for fine changes
    hidden: int = 256
    seed: int = 0
    extra: dict = field(default_factory=dict)


class DDPG:
    """The agent (see the module's text): actor, twin critics and their targets, with their optimisers
    and the observations' normalisation."""

    def __init__(self, config: DDPGConfig | None = None, obs_dim: int = OBS_DIM, act_dim: int = ACT_DIM):
        self.cfg = config or DDPGConfig()
        self.obs_dim, self.act_dim = obs_dim, act_dim
        seed_everything(self.cfg.seed)
        torch.set_num_threads(1)
        self.actor = mlp(obs_dim, act_dim, self.cfg.hidden, nn.Tanh())
        self.critic = mlp(obs_dim + act_dim, 1, self.cfg.hidden)
        self.critic2 = mlp(obs_dim + act_dim, 1, self.cfg.hidden)
        self.actor_target = copy.deepcopy(self.actor)
        self.critic_target = copy.deepcopy(self.critic)
        self.critic2_target = copy.deepcopy(self.critic2)
        self.anchor: nn.Module | None = None  # the cloned actor, frozen, once the DDPG phase starts
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=self.cfg.actor_lr)
        self.critic_opt = torch.optim.Adam([*self.critic.parameters(), *self.critic2.parameters()],
                                           lr=self.cfg.critic_lr)
        self.norm = RunningNorm(obs_dim)
        self.rng = np.random.default_rng(self.cfg.seed)
        self.updates = 0
        self.choice_drift = 0.0

    # --- acting ----------------------------------------------------------------------

    @torch.no_grad()
    def act(self, obs: np.ndarray, explore: bool = False, actor: nn.Module | None = None) -> np.ndarray:
        """The action for one observation (``actor``: another network than the one learning)."""
        a = (actor or self.actor)(torch.from_numpy(self.norm(obs))[None]).numpy()[0]
        if explore and not self.cfg.choice:
            a = a + self.rng.normal(0.0, self.cfg.noise, a.shape)
        elif explore:
            a[1:] = a[1:] + self.rng.normal(0.0, self.cfg.noise, self.act_dim - 1)
            self.choice_drift += (-self.cfg.choice_theta * self.choice_drift
                                  + self.cfg.choice_noise * np.sqrt(2 * self.cfg.choice_theta) * self.rng.normal())
            a[0] = a[0] + self.choice_drift
        return np.clip(a, -1.0, 1.0).astype(np.float32)

    def new_episode(self) -> None:
        """Exploration starts afresh: the choice's correlated noise from zero."""
        self.choice_drift = 0.0

    def freeze_anchor(self) -> None:
        """Keep the actor as it is now (the cloned policy) as what the DDPG phase is pulled back to."""
        self.anchor = copy.deepcopy(self.actor)
        for p in self.anchor.parameters():
            p.requires_grad_(False)

    # --- learning --------------------------------------------------------------------

    def _batch(self, buffer: ReplayBuffer):
        o, a, r, o2, d, demo, rn, on, dn, gn = buffer.sample(self.cfg.batch, self.rng)
        t = lambda x: torch.from_numpy(np.asarray(x, np.float32))  # noqa: E731
        return (t(self.norm(o)), t(a), t(r)[:, None], t(self.norm(o2)), t(d)[:, None], torch.from_numpy(demo),
                t(rn)[:, None], t(self.norm(on)), t(dn)[:, None], t(gn)[:, None])

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

    def q(self, o: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """The smaller of the twin critics' values (a pessimistic estimate)."""
        oa = torch.cat([o, a], 1)
        return torch.min(self.critic(oa), self.critic2(oa))

    def _target_value(self, o2: torch.Tensor) -> torch.Tensor:
        """The smaller target critic's value of the target actor's action, smoothed (TD3)."""
        cfg = self.cfg
        a2 = self.actor_target(o2)
        # Smoothing on the corrections only: noise on the choice would flip it, not smooth it.
        c = 1 if cfg.choice else 0
        a2[:, c:] = (a2[:, c:] + (torch.randn_like(a2[:, c:]) * cfg.policy_noise).clamp(-cfg.noise_clip, cfg.noise_clip)
                     ).clamp(-1.0, 1.0)
        oa2 = torch.cat([o2, a2], 1)
        return torch.min(self.critic_target(oa2), self.critic2_target(oa2))

    def update(self, buffer: ReplayBuffer, train_actor: bool = True) -> dict[str, float]:
        """One gradient step of the critics on a batch from ``buffer``, and of the actor where
        ``train_actor`` and the policy delay say so; the losses and figures of the step by name."""
        cfg = self.cfg
        o, a, r, o2, d, demo, rn, on, dn, gn = self._batch(buffer)
        with torch.no_grad():
            target = r + cfg.gamma * (1 - d) * self._target_value(o2)
            if cfg.n_step > 1:
                # A collision seconds after a choice of turning point reaches that choice's
                # value n steps at a time, not one.
                target_n = rn + gn * (1 - dn) * self._target_value(on)
        oa = torch.cat([o, a], 1)
        q1, q2 = self.critic(oa), self.critic2(oa)
        critic_loss = ((q1 - target) ** 2).mean() + ((q2 - target) ** 2).mean()
        if cfg.n_step > 1:
            critic_loss = critic_loss + cfg.n_step_weight * (((q1 - target_n) ** 2).mean() + ((q2 - target_n) ** 2).mean())
        self.critic_opt.zero_grad()
        critic_loss.backward()
        self.critic_opt.step()
        stats = {"critic_loss": float(critic_loss.detach())}
        self.updates += 1
        if train_actor and self.updates % cfg.policy_delay == 0:
            stats.update(self._update_actor(o, a, demo))
        self._soft_update(critics_only=not train_actor)  # while the critics warm up the actor is the cloned one
        return stats

    def _update_actor(self, o: torch.Tensor, a: torch.Tensor, demo: torch.Tensor) -> dict[str, float]:
        cfg = self.cfg
        pi = self.actor(o)
        q_pi = self.critic(torch.cat([o, pi], 1))
        scale = cfg.alpha / q_pi.abs().mean().detach().clamp(min=1e-3)
        loss = -scale * q_pi.mean()
        stats: dict[str, float] = {}
        with torch.no_grad():
            q_own = self.q(o, pi)
            decided = torch.zeros(len(o), dtype=torch.bool)
            if cfg.choice:
                # The choice: towards the turning point the critics rate higher, by a margin.
                near, far = pi.clone(), pi.clone()
                near[:, 0], far[:, 0] = -0.5, 0.5
                gain = self.q(o, far) - self.q(o, near)
                decided = gain.abs().squeeze(1) > cfg.choice_margin
                choice = torch.where(gain.squeeze(1) > 0, 0.5, -0.5)
        if decided.any():
            loss = loss + ((pi[decided, 0] - choice[decided]) ** 2).mean()
            stats["choice_decided"] = float(decided.float().mean())
        # Cloning terms: towards the demonstration where the critics rate it at least as high
        # as the actor's own action (Q-filter), and towards the cloned actor; the choice is
        # left to the term above where the critics decided it.
        keep = torch.ones_like(pi)
        keep[decided, 0] = 0.0
        if demo.any() and cfg.bc_weight > 0:
            with torch.no_grad():
                better = (self.q(o, a) >= q_own).squeeze(1) & demo
            if better.any():
                loss = loss + cfg.bc_weight * (((pi - a) ** 2) * keep)[better].sum(1).mean()
            stats["bc_share"] = float(better.float().sum() / demo.float().sum())
        if self.anchor is not None and cfg.anchor_weight > 0:
            # Not Q-filtered: the critics' error on the corrections is of the order of the
            # returns themselves (measured: see train.critic_error), and a filter that
            # trusts them lets the millimetre corrections drift within twenty episodes.
            cloned = self.anchor(o)
            loss = loss + cfg.anchor_weight * (((pi - cloned) ** 2) * keep).sum(1).mean()
        self.actor_opt.zero_grad()
        loss.backward()
        self.actor_opt.step()
        stats["actor_loss"] = float(loss.detach())
        return stats

    def _soft_update(self, critics_only: bool = False) -> None:
        pairs = [(self.critic, self.critic_target), (self.critic2, self.critic2_target)]
        if not critics_only:
            pairs.append((self.actor, self.actor_target))
        with torch.no_grad():
            for net, tgt in pairs:
                for p, tp in zip(net.parameters(), tgt.parameters()):
                    tp.mul_(1 - self.cfg.tau).add_(self.cfg.tau * p)

    # --- checkpoints -----------------------------------------------------------------

    def state(self, **extra) -> dict:
        """Everything the agent is (networks, optimisers, normalisation, settings), with ``extra``, as a
        checkpoint torch can save."""
        return {"version": CHECKPOINT_VERSION, "obs_dim": self.obs_dim, "act_dim": self.act_dim, "hidden": self.cfg.hidden,
                "residual_deg": RESIDUAL_DEG,
                "actor": self.actor.state_dict(), "critic": self.critic.state_dict(), "critic2": self.critic2.state_dict(),
                "actor_target": self.actor_target.state_dict(), "critic_target": self.critic_target.state_dict(),
                "critic2_target": self.critic2_target.state_dict(),
                "anchor": None if self.anchor is None else self.anchor.state_dict(), "updates": self.updates,
                "actor_opt": self.actor_opt.state_dict(), "critic_opt": self.critic_opt.state_dict(),
                "norm": self.norm.state(), "config": self.cfg.__dict__, **extra}

    def load_state(self, state: dict, optimisers: bool = True) -> None:
        """Take a checkpoint's networks and normalisation, and its optimisers where ``optimisers``
        (older checkpoints lack some networks: those start from their peers)."""
        self.actor.load_state_dict(state["actor"])
        self.critic.load_state_dict(state["critic"])
        self.critic2.load_state_dict(state.get("critic2", state["critic"]))
        self.actor_target.load_state_dict(state.get("actor_target", state["actor"]))
        self.critic_target.load_state_dict(state.get("critic_target", state["critic"]))
        self.critic2_target.load_state_dict(state.get("critic2_target", state.get("critic2", state["critic"])))
        if state.get("anchor") is not None:
            self.freeze_anchor()
            self.anchor.load_state_dict(state["anchor"])
        self.updates = int(state.get("updates", 0))
        if optimisers and "actor_opt" in state:
            self.actor_opt.load_state_dict(state["actor_opt"])
            self.critic_opt.load_state_dict(state["critic_opt"])
        self.norm = RunningNorm.from_state(state["norm"], self.obs_dim)


# What acting and evaluation need of a checkpoint: no optimiser, target networks or history.
ACTING_KEYS = ("version", "obs_dim", "act_dim", "hidden", "residual_deg", "actor", "critic", "norm", "config",
               "config_hash", "episodes", "metrics", "start_metrics", "trained_s", "train_config", "selection")


def acting_part(state: dict) -> dict:
    """The entries of a checkpoint that acting and evaluation read."""
    return {k: state[k] for k in ACTING_KEYS if k in state}


def strip_checkpoint(src, dst) -> None:
    """A small copy of a checkpoint for acting and evaluation: no optimiser or target networks."""
    torch.save(acting_part(torch.load(src, map_location="cpu", weights_only=True)), dst)


class CheckpointError(RuntimeError):
    """A checkpoint that is missing, unreadable or made for another observation/action layout."""


def _is(value, expected: int | float) -> bool:
    """``value`` is the number ``expected`` (a checkpoint's entry may hold anything: a tensor, text)."""
    return type(value) in (int, float) and value == expected


def load_policy(path, hidden: int | None = None) -> DDPG:
    """A DDPG agent from a checkpoint file, for acting; CheckpointError names the file.

    Read with ``weights_only``: a checkpoint is tensors, numbers, strings and lists, and torch
    then refuses a pickle that would run code when read (a file from elsewhere may)."""
    from pathlib import Path

    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint {path} does not exist (train one with `hycosim train`)")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        raise CheckpointError(f"checkpoint {path} is not readable: {exc}") from None
    if not isinstance(state, dict) or not _is(state.get("version"), CHECKPOINT_VERSION):
        raise CheckpointError(f"checkpoint {path} is not a hycosim DDPG checkpoint of version {CHECKPOINT_VERSION}")
    if not (_is(state.get("obs_dim"), OBS_DIM) and _is(state.get("act_dim"), ACT_DIM)):
        raise CheckpointError(f"checkpoint {path} expects {str(state.get('obs_dim'))[:20]} observations and "
                              f"{str(state.get('act_dim'))[:20]} actions; this policy has {OBS_DIM} and {ACT_DIM}")
    if not _is(state.get("residual_deg", 15.0), RESIDUAL_DEG):
        raise CheckpointError(f"checkpoint {path} was trained for joint corrections of "
                              f"±{str(state.get('residual_deg', 15.0))[:20]}°; this policy applies ±{RESIDUAL_DEG}° "
                              "(retrain with `hycosim train`)")
    width = state.get("hidden", hidden or 256)
    if type(width) is not int or not 1 <= width <= 4096:
        raise CheckpointError(f"checkpoint {path}: its networks' width {str(width)[:20]} is not a whole number "
                              "from 1 to 4096")
    agent = DDPG(DDPGConfig(hidden=width))
    try:
        agent.load_state(state, optimisers=False)
    except (RuntimeError, KeyError, TypeError, ValueError) as exc:
        raise CheckpointError(f"checkpoint {path} does not fit the networks: {exc}") from None
    agent.meta = {k: v for k, v in state.items() if k in ("metrics", "config_hash", "episodes", "trained_s")}
    return agent
