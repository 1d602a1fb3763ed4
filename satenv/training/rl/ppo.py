"""The lean batched PPO learner (PPO, IPPO, MAPPO) over ``satenv.make_vec`` arrays, read top to bottom.

    python -m satenv.training.rl.ppo --task platoon-tplf30-random-cw --budget 2000000 \\
        --out-dir runs/tplf_lean
    python -m satenv.training.rl.ppo --out-dir runs/tplf_lean --resume --budget 4000000
    tensorboard --logdir runs/tplf_lean/tb

One iteration collects ``n_steps`` decisions of ``num_envs`` copies of the task's env (every agent of
every copy at once: observations and actions are ``(num_envs, n_agents, dim)`` arrays, stepped by
:class:`satenv.vector.SatVectorEnv`), then runs ``n_epochs`` passes of clipped-PPO minibatch updates
over them. Budgets count agent-steps (one agent's one decision). Read in this order:

1. configuration (:class:`LeanConfig`; the fields every trainer shares come from
   :class:`satenv.training.config.RunConfig`); ``--variant`` picks the parameters:

   * ``ppo``   one actor and one critic shared by every agent, the critic on the agent's own
     observation (what SB3 PPO trains through ``satenv.training.vec_env.SatVecEnv``);
   * ``ippo``  per-agent actor and critic parameters (independent learners), local critics;
   * ``mappo`` a shared actor and a centralised critic on the global state (``vec.state()``)
     concatenated with the agent's observation;

2. defaults chosen for a ``[-1, 1]`` thrust box: the action is a Gaussian whose mean is
   ``tanh`` of the actor's output (initialised near zero thrust) with initial std
   ``init_std = 0.25``, clipped to the box by the env; γ matched to the horizon: ``gamma = 1 -
   gamma_k / max_steps`` when ``--gamma`` is not given (the return then weighs a reward at the end of
   an episode by about ``exp(-gamma_k)``; ``gamma_k = 3``: 5 %);
3. normalisation in the loop: rewards divided by the running std of the discounted return (SB3
   ``VecNormalize``'s rule) and the central critic's state by running mean / variance (frozen during
   an iteration, updated after it), both clipped to ``clip_obs``. Observations keep the envs' own
   fixed scales (every env divides positions and velocities by constants of its task) unless
   ``--norm-obs``: measured on validation seeds (700000-700019, 3 M agent-steps, training seed 0) of
   the section 5.1 platoon's first rung, running statistics fed by the wide early episodes left the
   policy drifting hundreds of metres (0/20, final error 567 m with 10 epochs of 1,024-agent-step
   minibatches) where fixed scales solved it (20/20, 0.74 m); the earlier 2 epochs of 4,096 learned
   too slowly there (approx. KL 1e-4 per iteration; 0/20, 149 m without running statistics), and on the
   TPLF training task the new defaults reached 0.9 training success by 1.2 M agent-steps on the seed
   the earlier ones left at 0/20 after 10 M;
4. the rollout (:func:`collect`): truncated episodes bootstrap from the critic's value of the
   last observation; finished copies are reset at once;
5. GAE (:func:`gae`) and the update (:func:`update`), large minibatches (``minibatch_size`` agent-steps);
6. checkpoints (``checkpoints/step_<N>/``, safetensors + npz + JSON, no pickle) every
   ``checkpoint_every`` agent-steps and at the end: ``--resume`` continues bit for bit;
7. logs: TensorBoard (``tb/``) and ``progress.jsonl`` (agent-steps, mean episode return, success);
8. the policy folder ``final/`` (:func:`satenv.training.policy.save_artifacts`, with ``eval.json`` on the
   held-out test seeds); ``ippo`` writes one folder per agent in ``final/agents/<agent>/`` (the
   folder format holds one shared actor) and its evaluation in ``final/eval.json``.

Torch runs on ``--torch-threads`` threads (default 1: measured, a second thread only competes with
the env for the other core). Before it starts, the run prints its size: budget, iterations and the
expected wall time at a rate measured on a throwaway iteration.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from satenv.training import runfolder
from satenv.training.config import RunConfig, check_int, check_number, config_from_json
from satenv.training.rl.nets import (
    ActorCritic,
    FlatArrays,
    adam_step,
    export_actor,
    from_copies,
    mlp_backward,
    mlp_forward,
    scratch,
    to_copies,
)

__all__ = ["LeanConfig", "RunningMeanStd", "VARIANTS", "gae", "horizon_gamma", "load_init_actor", "main", "train",
           "warm_start"]

VARIANTS = ("ppo", "ippo", "mappo")


def horizon_gamma(max_steps: int, k: float) -> float:
    """γ whose effective horizon ``1 / (1 - γ)`` is ``max_steps / k`` decisions."""
    return 1.0 - k / max_steps


# --------------------------------------------------------------------------- 1. configuration
@dataclass(frozen=True)
class LeanConfig(RunConfig):
    """One lean PPO run (module docstring). Agent-steps count one agent's one decision."""

    variant: str = "ppo"
    """``ppo`` (shared actor and local critic), ``ippo`` (per-agent parameters), ``mappo``
    (shared actor, centralised critic)."""
    budget: int = 1_000_000
    """Agent-steps to train for, rounded up to whole iterations (``num_envs * n_agents * n_steps``)."""
    num_envs: int = 64
    """Env copies stepped together."""
    n_steps: int = 32
    """Decisions per copy per iteration."""
    minibatch_size: int = 1024
    """Agent-steps per gradient step (rounded down to whole copies-steps of ``n_agents`` rows)."""
    n_epochs: int = 10
    """Passes over each iteration's data (with ``minibatch_size``: 40 gradient steps per 4,096 agent-steps)."""
    gamma: float | None = None
    """Discount; ``None``: ``1 - gamma_k / max_steps`` (:func:`horizon_gamma`)."""
    gamma_k: float = 3.0
    """Episodes per effective horizon when ``gamma`` is not given."""
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    target_kl: float | None = None
    """Stop an iteration's epochs at the first minibatch whose approximate KL to the collecting policy
    exceeds ``1.5 * target_kl`` (SB3's rule; ``None``: every epoch runs)."""
    init_std: float = 0.25
    """Initial action standard deviation on the ``[-1, 1]`` box."""
    norm_obs: bool = False
    """Observations by running mean / variance; off: the envs' own fixed scales (module docstring)."""
    norm_reward: bool = True
    clip_obs: float = 10.0
    """Clip of the normalised observations and rewards."""
    checkpoint_every: int = 500_000
    """Agent-steps between checkpoints (0: only at the end)."""
    lagrangian: bool = False
    """PPO-Lagrangian on the ``safety_cost`` info (:mod:`satenv.training.rl.lagrangian`)."""
    lagrange_lr: float = 0.05
    """Its dual step size."""
    cost_budget: float | None = None
    """Its episode safety-cost budget per agent; ``None``: the task's ``cost_budget``."""
    warm_start: str | None = None
    """A lean run's folder (its newest checkpoint) or one of its ``checkpoints/step_<N>`` whose network
    and statistics this run starts from (:func:`warm_start`): training along a ladder, rung after rung."""
    init_actor: str | None = None
    """A policy folder (e.g. an imitation network) whose actor this run's actor starts from and keeps
    the layout of (:func:`load_init_actor`): its hidden sizes and activation, its feature map and frozen
    observation normalisation (the actor's input, and the critic's), its action map and terminal
    feedback (applied to every sampled action); the critic is a new ``net_arch`` MLP. Not with
    ``norm_obs`` or ``warm_start``."""
    actor_lr: float | None = None
    """The actor's (and its std's) learning rate; ``None``: ``lr``, which the critic always takes (a
    seeded actor is fine-tuned at a smaller rate than its new critic learns)."""
    critic_warmup: int = 0
    """Agent-steps at the start of a run in which only the critic learns (the actor and its std keep
    their values): a seeded actor is not moved by the advantages of an untrained critic."""
    out_dir: str = "runs/lean_ppo"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.variant not in VARIANTS:
            raise ValueError(f"variant must be one of {VARIANTS}, got {self.variant!r}")
        for name in ("budget", "num_envs", "n_steps", "minibatch_size", "n_epochs"):
            check_int(name, getattr(self, name), minimum=1)
        check_int("checkpoint_every", self.checkpoint_every, minimum=0)
        check_int("critic_warmup", self.critic_warmup, minimum=0)
        if self.gamma is not None:
            check_number("gamma", self.gamma, 0.0, 1.0)
        if self.target_kl is not None:
            check_number("target_kl", self.target_kl, 0.0, math.inf)      # inf: no stop, as None
        if self.actor_lr is not None:
            check_number("actor_lr", self.actor_lr, 0.0, math.inf)
            if not math.isfinite(self.actor_lr):
                raise ValueError(f"actor_lr must be a finite number > 0, got {self.actor_lr!r}")
        for name, lo, hi in (("gamma_k", 0.0, math.inf), ("gae_lambda", 0.0, 1.0), ("clip_range", 0.0, math.inf),
                             ("max_grad_norm", 0.0, math.inf), ("init_std", 0.0, 10.0), ("clip_obs", 0.0, math.inf)):
            check_number(name, getattr(self, name), lo, hi)
        for name in ("ent_coef", "vf_coef"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not 0 <= v < math.inf:
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        for name in ("norm_obs", "norm_reward", "lagrangian"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be a bool, got {getattr(self, name)!r}")
        if self.warm_start is not None and (not isinstance(self.warm_start, str) or not self.warm_start):
            raise ValueError(f"warm_start must be a lean run's folder or checkpoint path, got {self.warm_start!r}")
        if self.init_actor is not None:
            if not isinstance(self.init_actor, str) or not self.init_actor:
                raise ValueError(f"init_actor must be a policy folder's path, got {self.init_actor!r}")
            if self.norm_obs or self.warm_start is not None:
                raise ValueError("init_actor keeps the policy folder's own observation normalisation and weights: "
                                 f"not with norm_obs=True or warm_start (got norm_obs={self.norm_obs!r}, "
                                 f"warm_start={self.warm_start!r})")


# --------------------------------------------------------------------------- 3. normalisation
class RunningMeanStd:
    """Running mean and variance over the leading axes (Chan's parallel update), float64."""

    def __init__(self, shape: tuple[int, ...] = ()) -> None:
        self.mean, self.var, self.count = np.zeros(shape), np.ones(shape), 1e-4

    def update(self, x: np.ndarray) -> None:
        x = x.reshape(-1, *self.mean.shape)
        n, mean, var = x.shape[0], x.mean(0), x.var(0)
        delta, total = mean - self.mean, self.count + n
        self.mean = self.mean + delta * n / total
        self.var = (self.var * self.count + var * n + delta**2 * self.count * n / total) / total
        self.count = total

    def normalize(self, x: np.ndarray, clip: float) -> np.ndarray:
        return np.clip((x - self.mean) / np.sqrt(self.var + 1e-8), -clip, clip).astype(np.float32)

    def to_json(self) -> dict[str, Any]:
        return {"mean": self.mean.tolist(), "var": self.var.tolist(), "count": self.count}

    def load_json(self, d: dict[str, Any]) -> None:
        self.mean, self.var = np.asarray(d["mean"], dtype=np.float64), np.asarray(d["var"], dtype=np.float64)
        self.count = float(d["count"])


class Normalizers:
    """The run's running statistics: observations, central state, discounted return."""

    def __init__(self, obs_dim: int, state_dim: int, num_envs: int, n_agents: int) -> None:
        self.obs, self.state, self.ret = RunningMeanStd((obs_dim,)), RunningMeanStd((state_dim,)), RunningMeanStd()
        self.returns = np.zeros((num_envs, n_agents))    # the running discounted return per agent

    def to_json(self) -> dict[str, Any]:
        return {k: getattr(self, k).to_json() for k in ("obs", "state", "ret")}

    def load_json(self, d: dict[str, Any]) -> None:
        for k in ("obs", "state", "ret"):
            getattr(self, k).load_json(d[k])


# --------------------------------------------------------------------------- the run's state
class Run:
    """Everything a run carries between iterations (what a checkpoint saves)."""

    def __init__(self, cfg: LeanConfig, vec: Any, gamma: float) -> None:
        self.cfg, self.vec, self.gamma = cfg, vec, gamma
        m = vec.n_agents
        self.env_obs_dim = vec.single_observation_space.shape[0]
        self.act_dim = vec.single_action_space.shape[0]
        self.init_policy = load_init_actor(cfg.init_actor, self.env_obs_dim, self.act_dim) if cfg.init_actor else None
        spec = (self.init_policy.actor.spec if self.init_policy
                else {"obs_dim": self.env_obs_dim, "hidden": None, "activation": "tanh"})
        self.obs_dim = spec["obs_dim"]
        """The actor's input width: the observation's, or the init policy's featurised one."""
        self.central = cfg.variant == "mappo"
        self.state_dim = vec.state().shape[1] if self.central else 0
        torch.manual_seed(cfg.seed)
        self.net = ActorCritic(self.obs_dim, self.act_dim, self.state_dim + self.obs_dim, cfg.net_arch,
                               m if cfg.variant == "ippo" else 1, cfg.init_std, spec["hidden"], spec["activation"])
        if self.init_policy:
            _copy_actor(self.net, self.init_policy.actor)
        self.opt = torch.optim.Adam(self.net.parameters(), lr=cfg.lr, eps=1e-5)
        self.params = FlatArrays(self.net, self.net.flat.numpy())   # numpy views of the parameters
        self.moments = (torch.zeros_like(self.net.flat), torch.zeros_like(self.net.flat))   # Adam's, flat
        self.buffers: dict[str, np.ndarray] = {}         # the update's work arrays (nets.scratch)
        self.gen = torch.Generator().manual_seed(cfg.seed)
        self.norm = Normalizers(self.obs_dim, max(self.state_dim, 1), cfg.num_envs, m)
        self.steps = 0                                   # agent-steps done
        self.obs, _ = vec.reset(seed=cfg.seed)
        if self.init_policy:
            _check_seeded(self)
        self.episode = {"ret": np.zeros(cfg.num_envs), "len": np.zeros(cfg.num_envs, dtype=np.int64),
                        "collided": np.zeros(cfg.num_envs, dtype=bool)}
        self.dual = _dual(cfg)
        if self.dual is not None:
            self.episode["cost"] = np.zeros(cfg.num_envs)


def load_init_actor(folder: str, obs_dim: int, act_dim: int) -> Any:
    """The :class:`satenv.training.policy.LearnedPolicy` of policy folder ``folder`` (the network alone)
    for a run's ``init_actor``: a squashed MLP actor of a hidden activation the lean networks
    implement, for this env's observation and action sizes. Its action map and terminal feedback
    stay part of the policy: the run applies them to each sampled action (:func:`_env_action`)."""
    from satenv.training.policy import load
    from satenv.training.rl.nets import ACTIVATIONS

    policy = load(folder, shielded=False)
    spec = getattr(policy.actor, "spec", {})
    problems = []
    if spec.get("type") != "mlp" or not spec.get("squash") or spec.get("activation") not in ACTIVATIONS:
        problems.append(f"its actor {spec} is not a squashed MLP with activation in {sorted(ACTIVATIONS)}")
    if policy.obs_shape != (obs_dim,) or policy.action_shape != (act_dim,):
        problems.append(f"its observation / action shapes {policy.obs_shape} / {policy.action_shape} are not "
                        f"the env's {(obs_dim,)} / {(act_dim,)}")
    if problems:
        raise ValueError(f"init_actor {folder}: " + "; ".join(problems))
    return policy


def _maps_config(policy: Any) -> dict[str, Any]:
    """The ``config.json`` fields a policy folder's loader rebuilds ``policy``'s feature map, action
    map and terminal feedback from (:mod:`satenv.training.policy`)."""
    from dataclasses import asdict

    out: dict[str, Any] = {}
    if policy.features is not None:
        f = policy.features
        out.update(obs_symlog_scale=f.symlog_scale, obs_symlog_dims=f.symlog_dims, obs_drop_dims=list(f.drop_dims))
    if policy.action_map is not None:
        out["action_power"] = policy.action_map.power
    if policy.terminal is not None:
        out["terminal"] = asdict(policy.terminal)
    return out


def _env_action(run: Run, obs: np.ndarray, act: np.ndarray) -> np.ndarray:
    """What the env is given for the sampled actions ``act`` (clipped to the box) at the raw
    observations ``obs``: the init policy's action map and terminal feedback applied
    (:meth:`satenv.training.policy.LearnedPolicy.env_action`; to the learner they are part of the env,
    so its log-probabilities stay those of ``act``)."""
    return act if run.init_policy is None else run.init_policy.env_action(obs, act)


def _copy_actor(net: ActorCritic, actor: Any) -> None:
    """Every weight copy of ``net``'s actor from an :class:`satenv.training.actor.MLPActor` of its shape."""
    with torch.no_grad():
        for w, b, layer in zip(net.actor.weights, net.actor.biases, actor.linear_layers(), strict=True):
            w.copy_(layer.weight.T.expand_as(w))
            b.copy_(layer.bias.expand_as(b))


SEEDED_ACTION_TOL = 1e-4
"""Largest difference allowed between a seeded run's first actions and its init policy's."""


def _check_seeded(run: Run) -> None:
    """The seeded run's mean actions at its first observations are its init policy's (``ValueError``
    otherwise: the copy or the input map is wrong)."""
    obs = run.obs
    mine = _env_action(run, obs, _actor_mean(run, _norm_obs(run, obs)))
    theirs = run.init_policy.predict(obs.reshape(-1, obs.shape[-1])).reshape(mine.shape)
    diff = float(np.abs(mine - theirs).max())
    if not diff <= SEEDED_ACTION_TOL:
        raise ValueError(f"init_actor {run.cfg.init_actor}: the seeded actor does not reproduce the folder's "
                         f"actions (max difference {diff:.3g} > SEEDED_ACTION_TOL {SEEDED_ACTION_TOL})")


def _dual(cfg: LeanConfig) -> Any:
    """The Lagrange multiplier of a ``lagrangian`` run (``None`` otherwise)."""
    from satenv import tasks
    from satenv.training.rl.lagrangian import Lagrange

    if not cfg.lagrangian:
        return None
    budget = cfg.cost_budget if cfg.cost_budget is not None else (tasks.get(cfg.task).cost_budget if cfg.task else None)
    if budget is None:
        raise ValueError(f"lagrangian: task {cfg.task!r} sets no cost_budget; give cost_budget")
    return Lagrange(budget, cfg.lagrange_lr)


# --------------------------------------------------------------------------- 4. the rollout
def _critic_in(run: Run, obs_n: np.ndarray, state: np.ndarray | None) -> np.ndarray:
    """The critic's input ``(B, M, C)``: the normalised observation, after the normalised global
    state for a centralised critic."""
    if not run.central:
        return obs_n
    s = run.norm.state.normalize(state, run.cfg.clip_obs)     # the state has no scale of its own: always
    return np.concatenate([np.broadcast_to(s[:, None], (*obs_n.shape[:2], s.shape[-1])), obs_n], axis=-1)


def _norm_obs(run: Run, obs: np.ndarray) -> np.ndarray:
    """The actor's input: the init policy's features and frozen normalisation, the running
    statistics' (``norm_obs``), or the observation itself."""
    if run.init_policy is not None:
        return run.init_policy.network_input(obs)
    return run.norm.obs.normalize(obs, run.cfg.clip_obs) if run.cfg.norm_obs else obs.astype(np.float32)


def _actor_mean(run: Run, obs: np.ndarray) -> np.ndarray:
    """The policy's mean action ``(n, M, A)`` on normalised observations ``(n, M, obs)`` (numpy,
    the same function as ``run.net.mean``)."""
    p = run.params
    out = mlp_forward(p.actor_w, p.actor_b, to_copies(obs, len(p.log_std)), activation=run.net.actor.activation)[-1]
    return from_copies(np.tanh(out, out=out), obs.shape[0])


def _value(run: Run, critic_obs: np.ndarray, tag: str | None = None) -> np.ndarray:
    """The critic's ``V (n, M)`` on its inputs ``(n, M, C)`` (numpy, the same as ``run.net.value``;
    ``tag``: its hidden activations in the run's work arrays of that tag)."""
    p = run.params
    x = to_copies(critic_obs, len(p.log_std))
    out = mlp_forward(p.critic_w, p.critic_b, x, run.buffers if tag else None, tag or "")[-1]
    return from_copies(out, critic_obs.shape[0])[..., 0]


def collect(run: Run, timers: dict[str, float]) -> dict[str, Any]:
    """``n_steps`` decisions of every copy with the current policy; returns the rollout (numpy
    float32 arrays ``(T, B, M, ...)``) and the finished episodes' returns and successes."""
    cfg, vec = run.cfg, run.vec
    T, (B, M) = cfg.n_steps, run.obs.shape[:2]
    scenario = vec.scenario
    raw_obs = np.empty((T, B, M, run.obs_dim), dtype=np.float32) if cfg.norm_obs else None
    critic_obs = np.empty((T, B, M, run.state_dim + run.obs_dim), dtype=np.float32)
    actions = np.empty((T, B, M, run.act_dim), dtype=np.float32)
    logp = np.empty((T, B, M), dtype=np.float32)
    rewards = np.empty((T, B, M), dtype=np.float32)
    dones = np.empty((T, B), dtype=bool)
    boot: list[tuple[int, np.ndarray, np.ndarray]] = []   # (t, truncated copies, their critic input)
    states = np.empty((T, B, run.state_dim)) if run.central else None
    finished: dict[str, list[float]] = {"return": [], "success": [], "length": [], "cost": []}
    std = np.exp(run.params.log_std)                      # (K, A)
    log_norm = run.params.log_std.sum(-1) + np.float32(0.5 * run.act_dim * math.log(2 * math.pi))   # (K,)
    noise = torch.randn((T, B, M, run.act_dim), generator=run.gen).numpy()   # the iteration's draws at once
    np.subtract(-0.5 * (noise * noise).sum(-1), log_norm, out=logp)
    np.multiply(noise, std, out=actions)
    obs = run.obs
    for t in range(T):
        t0 = time.perf_counter()
        if raw_obs is not None:
            raw_obs[t] = obs
        if run.central or cfg.norm_obs or run.init_policy is not None:
            obs_n = _norm_obs(run, obs)
            state = vec.state() if run.central else None
            if run.central:
                states[t] = state
            critic_obs[t] = _critic_in(run, obs_n, state)
        else:                                            # the critic's input is the observation itself
            obs_n = critic_obs[t]
            obs_n[...] = obs
        actions[t] += _actor_mean(run, obs_n)
        act = _env_action(run, obs, actions[t].clip(-1.0, 1.0))
        t1 = time.perf_counter()
        obs, rew, term, trunc, info = vec.step(act)
        t2 = time.perf_counter()
        timers["env"] += t2 - t1
        done = term[:, 0] | trunc[:, 0]
        ep = run.episode
        ep["ret"] += rew.mean(1)
        ep["len"] += 1
        ep["collided"] |= np.asarray(info["collision"]).reshape(B, -1).any(1)
        if cfg.norm_reward:
            run.norm.returns = run.norm.returns * run.gamma + rew
            run.norm.ret.update(run.norm.returns)
            run.norm.returns[done] = 0.0
            rew = np.clip(rew / np.sqrt(run.norm.ret.var + 1e-8), -cfg.clip_obs, cfg.clip_obs)
        if run.dual is not None:
            ep["cost"] += np.asarray(info["safety_cost"]).mean(1)
            rew = run.dual.penalise(rew, info["safety_cost"])
        rewards[t], dones[t] = rew, done
        if done.any():
            idx = np.flatnonzero(done)
            truncated = idx[trunc[idx, 0]]
            if truncated.size:    # bootstrap from the last observation (normalised as this iteration's)
                last_state = vec.state()[truncated] if run.central else None
                boot.append((t, truncated, _critic_in(run, _norm_obs(run, obs[truncated]), last_state)))
            err = np.linalg.norm(np.asarray(info["tracking_error"])[idx, :, :3], axis=-1).max(1)
            voided = ep["collided"][idx] & bool(scenario.collision_voids_success)
            finished["return"] += ep["ret"][idx].tolist()
            finished["length"] += ep["len"][idx].tolist()
            if run.dual is not None:
                finished["cost"] += ep["cost"][idx].tolist()
                ep["cost"][idx] = 0.0
            finished["success"] += ((err <= scenario.success_tol) & ~voided).astype(float).tolist()
            ep["ret"][idx], ep["len"][idx], ep["collided"][idx] = 0.0, 0, False
            t3 = time.perf_counter()
            obs, _ = vec.reset(indices=idx)
            timers["env"] += time.perf_counter() - t3
        timers["forward"] += t1 - t0
    run.obs = obs
    last = _critic_in(run, _norm_obs(run, obs), vec.state() if run.central else None)
    if cfg.norm_obs:   # the statistics move after the iteration that used them
        run.norm.obs.update(raw_obs)
    if run.central:
        run.norm.state.update(states)
    return {"critic_obs": critic_obs, "actions": actions, "logp": logp, "rewards": rewards, "dones": dones,
            "boot": boot, "last": last, "finished": finished}


# --------------------------------------------------------------------------- 5. GAE and the update
def gae(rewards: np.ndarray, values: np.ndarray, last_value: np.ndarray, dones: np.ndarray,
        gamma: float, lam: float) -> tuple[np.ndarray, np.ndarray]:
    """Advantages and returns ``(T, B, M)`` (numpy float32); ``dones (T, B)`` end a copy's episode
    after step t (a truncation's bootstrap is already in its reward)."""
    adv = np.empty_like(rewards)
    live = (~dones)[..., None].astype(rewards.dtype)      # (T, B, 1)
    running = np.zeros_like(last_value)
    next_value = last_value
    for t in range(rewards.shape[0] - 1, -1, -1):
        delta = rewards[t] + gamma * next_value * live[t] - values[t]
        running = delta + gamma * lam * live[t] * running
        adv[t] = running
        next_value = values[t]
    return adv, adv + values


def _adam_moments(run: Run) -> tuple[np.ndarray, np.ndarray, int]:
    """Adam's flat first and second moments (numpy views of ``run.moments``) and its step count.
    ``run.opt.state`` (what a checkpoint saves and restores) holds per-parameter views of them; a
    state restored from a checkpoint is copied in first."""
    flat = run.net.flat
    steps = 0
    for p in run.net.parameters():
        start = (p.data_ptr() - flat.data_ptr()) // flat.element_size()
        m, v = (buf[start:start + p.numel()].view(p.shape) for buf in run.moments)
        state = run.opt.state.get(p)
        if state:
            steps = int(float(state["step"]))
            if state["exp_avg"].data_ptr() == m.data_ptr():
                continue
            m.copy_(state["exp_avg"])
            v.copy_(state["exp_avg_sq"])
        run.opt.state[p] = {"step": torch.tensor(float(steps)), "exp_avg": m, "exp_avg_sq": v}
    return run.moments[0].numpy(), run.moments[1].numpy(), steps


def _set_adam_steps(run: Run, steps: int) -> None:
    """Adam's step count into every parameter's optimizer state (what a checkpoint saves)."""
    for state in run.opt.state.values():
        state["step"].fill_(float(steps))


def _ppo_grad(run: Run, grads: FlatArrays, cin: np.ndarray, actions: np.ndarray, old_logp: np.ndarray,
              adv: np.ndarray, returns: np.ndarray) -> tuple[float, float, float, float]:
    """One minibatch of ``rows`` copies-steps (``cin (rows, M, C)``, ``actions (rows, M, A)``, the
    rest ``(rows, M)``): write the clipped-PPO loss's gradient into ``grads``; returns the policy
    loss, value loss, clip fraction and approximate KL. The loss is

        pg + vf_coef * 0.5 * mean((V - returns)^2) - ent_coef * entropy,
        pg = mean(max(-a * ratio, -a * clip(ratio, 1 - clip_range, 1 + clip_range)))

    with ``a`` the advantages normalised over the minibatch; forward and backward by hand in numpy
    (tests/test_lean_nets.py checks the gradient against autograd)."""
    cfg, p = run.cfg, run.params
    k = len(p.log_std)
    x = to_copies(cin, k)                                  # (K, R, C); the actor reads the observation part
    activation = run.net.actor.activation
    acts = mlp_forward(p.actor_w, p.actor_b, x[..., run.state_dim:], run.buffers, "actor", activation)
    mean = np.tanh(acts[-1])                               # (K, R, A)
    log_std = p.log_std[:, None, :]
    inv_std = np.exp(-log_std)
    z = (to_copies(actions, k) - mean) * inv_std
    logp = -0.5 * (z * z).sum(-1) - log_std.sum(-1) - np.float32(0.5 * run.act_dim * math.log(2 * math.pi))
    log_ratio = logp - to_copies(old_logp[..., None], k)[..., 0]
    ratio = np.exp(log_ratio)                              # (K, R)
    a = to_copies(adv[..., None], k)[..., 0]
    a = (a - a.mean()) / (a.std(ddof=1) + np.float32(1e-8))
    n = a.size
    unclipped, clipped = -a * ratio, -a * np.clip(ratio, 1 - cfg.clip_range, 1 + cfg.clip_range)
    pg = float(np.maximum(unclipped, clipped).mean())
    d_logp = np.where(unclipped >= clipped, -a, 0.0).astype(np.float32) * ratio / np.float32(n)
    grads.log_std[:] = np.einsum("kr,kra->ka", d_logp, z * z - 1) - np.float32(cfg.ent_coef / k)
    d_out = (d_logp[..., None] * z * inv_std) * (1 - mean * mean)
    mlp_backward(p.actor_w, acts, d_out, grads.actor_w, grads.actor_b, run.buffers, "actor", activation)
    acts = mlp_forward(p.critic_w, p.critic_b, x, run.buffers, "critic")
    diff = acts[-1] - to_copies(returns[..., None], k)     # (K, R, 1)
    v_loss = 0.5 * float(np.mean(diff * diff))
    mlp_backward(p.critic_w, acts, diff * np.float32(cfg.vf_coef / n), grads.critic_w, grads.critic_b, run.buffers,
                 "critic")
    return pg, v_loss, float(np.mean(np.abs(ratio - 1) > cfg.clip_range)), float(np.mean((ratio - 1) - log_ratio))


def _rows(run: Run, name: str, x: np.ndarray, mb: np.ndarray) -> np.ndarray:
    """``x[mb]`` into the run's work array ``name`` (:func:`satenv.training.rl.nets.scratch`; ``mb`` from a
    permutation, always in range: ``mode="clip"`` spares numpy's bounds-checked copy through a buffer)."""
    return np.take(x, mb, axis=0, out=scratch(run.buffers, f"mb_{name}", (len(mb), *x.shape[1:])), mode="clip")


def _clip_grad_norm(grad: np.ndarray, max_norm: float) -> None:
    """``torch.nn.utils.clip_grad_norm_`` on the flat gradient."""
    total = math.sqrt(float(np.dot(grad, grad)))
    grad *= np.float32(min(max_norm / (total + 1e-6), 1.0))


def _learning_rates(run: Run) -> float | np.ndarray:
    """Adam's rate: ``lr``, or with ``actor_lr`` a flat array of the parameters' rates (the actor's
    weights and ``log_std`` at ``actor_lr``, the critic's at ``lr``)."""
    lr = run.opt.param_groups[0]["lr"]
    if run.cfg.actor_lr is None:
        return lr
    rates = FlatArrays(run.net, np.full_like(run.params.buf, lr))
    for a in (*rates.actor_w, *rates.actor_b, rates.log_std):
        a[...] = run.cfg.actor_lr
    return rates.buf


def update(run: Run, batch: dict[str, Any], timers: dict[str, float]) -> dict[str, float]:
    """GAE, then ``n_epochs`` passes of clipped-PPO minibatch steps over the iteration's data (the
    gradient by :func:`_ppo_grad`, the step by Adam over the flat parameters)."""
    cfg = run.cfg
    t0 = time.perf_counter()
    T, B, M = batch["rewards"].shape
    n = T * B
    cin = batch["critic_obs"].reshape(n, M, -1)
    rewards = batch["rewards"].copy()
    values = _value(run, cin, "values").reshape(T, B, M)
    for t, copies, c in batch["boot"]:
        rewards[t, copies] += run.gamma * _value(run, c)
    adv, returns = gae(rewards, values, _value(run, batch["last"]), batch["dones"], run.gamma, cfg.gae_lambda)
    actions, old_logp = batch["actions"].reshape(n, M, -1), batch["logp"].reshape(n, M)
    adv, returns = adv.reshape(n, M), returns.reshape(n, M)
    rows = max(1, min(n, cfg.minibatch_size // M))
    data = {"cin": cin, "actions": actions, "old_logp": old_logp, "adv": adv, "returns": returns}
    grads = FlatArrays(run.net, np.zeros_like(run.params.buf))
    exp_avg, exp_avg_sq, steps = _adam_moments(run)
    group = run.opt.param_groups[0]
    stats = np.zeros(4)                                    # policy loss, value loss, clip fraction, approx KL
    count = 0
    frozen = (*grads.actor_w, *grads.actor_b, grads.log_std) if run.steps < cfg.critic_warmup else ()
    lr = _learning_rates(run)
    kl_stop = math.inf if cfg.target_kl is None else 1.5 * cfg.target_kl
    stopped = False
    for _ in range(cfg.n_epochs):
        perm = torch.randperm(n, generator=run.gen).numpy()
        for start in range(0, n - rows + 1, rows):
            mb = perm[start:start + rows]
            mb_stats = _ppo_grad(run, grads, *(_rows(run, name, x, mb) for name, x in data.items()))
            stopped = mb_stats[3] > kl_stop                # too far from the collecting policy: no more steps
            if stopped:
                break
            stats += mb_stats
            for g in frozen:                               # the critic's warm-up: the actor keeps its values
                g[...] = 0.0
            _clip_grad_norm(grads.buf, cfg.max_grad_norm)
            steps += 1
            adam_step(run.params.buf, grads.buf, exp_avg, exp_avg_sq, steps, lr, group["betas"], group["eps"])
            count += 1
        if stopped:
            break
    _set_adam_steps(run, steps)
    timers["update"] += time.perf_counter() - t0
    names = ("policy_loss", "value_loss", "clip_fraction", "approx_kl")
    return {k: float(v) / max(count, 1) for k, v in zip(names, stats, strict=True)} | {
        "std": float(np.exp(run.params.log_std).mean()), "gradient_steps": count}


# --------------------------------------------------------------------------- 6. checkpoints
CHECKPOINT_TENSORS = "state.safetensors"
CHECKPOINT_ARRAYS = "env_state.npz"
CHECKPOINT_JSON = "state.json"


def save_checkpoint(run: Run, out: Path) -> Path:
    """``checkpoints/step_<N>/``: weights and Adam moments (safetensors), the env's episodes and
    the generators (npz), the statistics (JSON); written whole or not at all."""
    from safetensors.torch import save_file

    folder = out / "checkpoints" / f"step_{run.steps}"
    tmp = runfolder.staging(folder)
    tensors = {f"net.{k}": v.detach().contiguous() for k, v in run.net.state_dict().items()}
    names = dict(zip(map(id, run.net.parameters()), (k for k, _ in run.net.named_parameters()), strict=True))
    steps = {}
    for p, s in run.opt.state.items():
        tensors[f"adam.{names[id(p)]}.exp_avg"] = s["exp_avg"].contiguous()
        tensors[f"adam.{names[id(p)]}.exp_avg_sq"] = s["exp_avg_sq"].contiguous()
        steps[names[id(p)]] = float(s["step"])
    save_file(tensors, str(tmp / CHECKPOINT_TENSORS))
    arrays = {f"env.{k}": v for k, v in run.vec.get_state().items()}
    arrays.update({"obs": run.obs, "returns": run.norm.returns, "generator": run.gen.get_state().numpy(),
                   **{f"episode.{k}": v for k, v in run.episode.items()}})
    np.savez(tmp / CHECKPOINT_ARRAYS, **arrays)
    (tmp / CHECKPOINT_JSON).write_text(json.dumps({"steps": run.steps, "adam_steps": steps,
                                                   "norm": run.norm.to_json(),
                                                   "lam": run.dual.lam if run.dual else None}) + "\n")
    return runfolder.replace_folder(tmp, folder)


def latest_checkpoint(out: Path) -> Path | None:
    """The newest complete ``checkpoints/step_<N>`` (:func:`satenv.training.runfolder.latest_checkpoint`)."""
    found = runfolder.latest_checkpoint(out, CHECKPOINT_JSON)
    return found[1] if found else None


def _load_network(run: Run, folder: Path) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """Set ``run``'s network and running statistics from the checkpoint ``folder``; returns its
    tensors and metadata (shapes checked by torch)."""
    from safetensors.torch import load_file

    tensors = load_file(str(folder / CHECKPOINT_TENSORS))
    meta = json.loads((folder / CHECKPOINT_JSON).read_text())
    run.net.load_state_dict({k[4:]: v for k, v in tensors.items() if k.startswith("net.")})
    run.norm.load_json(meta["norm"])
    return tensors, meta


def load_checkpoint(run: Run, folder: Path) -> None:
    """Restore :func:`save_checkpoint` into a freshly built ``run`` (shapes checked by torch)."""
    try:
        tensors, meta = _load_network(run, folder)
        for name, p in run.net.named_parameters():
            if name in meta["adam_steps"]:
                run.opt.state[p] = {"step": torch.tensor(meta["adam_steps"][name]),
                                    "exp_avg": tensors[f"adam.{name}.exp_avg"].clone(),
                                    "exp_avg_sq": tensors[f"adam.{name}.exp_avg_sq"].clone()}
        with np.load(folder / CHECKPOINT_ARRAYS, allow_pickle=False) as d:
            data = {k: d[k] for k in d.files}
        run.vec.set_state({k[4:]: v for k, v in data.items() if k.startswith("env.")})
        run.obs, run.norm.returns = data["obs"].copy(), data["returns"].copy()
        run.gen.set_state(torch.from_numpy(data["generator"].copy()))
        run.episode = {k: data[f"episode.{k}"].copy() for k in run.episode}
        run.steps = int(meta["steps"])
        if run.dual is not None:
            run.dual.lam = float(meta["lam"])
    except (KeyError, ValueError, RuntimeError, OSError, TypeError) as err:
        raise runfolder.RunFolderError(f"--resume: the checkpoint {folder} is malformed or from another "
                                       f"config ({type(err).__name__}: {str(err)[:160]})") from None


def warm_start(run: Run, source: Path) -> Path:
    """Start ``run``'s network (weights and action std) and its running statistics from another lean
    run's checkpoint (``source``: the run's folder, its newest checkpoint, or one ``step_<N>``); the
    optimiser, the envs and the step counter start fresh. Returns the checkpoint read. The network
    must have this run's shapes (variant, observation and action sizes, ``net_arch``)."""
    folder = source if (source / CHECKPOINT_JSON).is_file() else latest_checkpoint(source)
    if folder is None:
        raise ValueError(f"warm_start: {source} holds no lean checkpoint (checkpoints/step_<N>/{CHECKPOINT_JSON})")
    try:
        _load_network(run, folder)
    except (KeyError, ValueError, RuntimeError, OSError) as err:
        raise ValueError(f"warm_start: the network of {folder} does not fit this run (variant "
                         f"{run.cfg.variant!r}, observation size {run.obs_dim}, action size {run.act_dim}, "
                         f"net_arch {run.cfg.net_arch}): {type(err).__name__}: {str(err)[:160]}") from None
    return folder


# --------------------------------------------------------------------------- 7.-8. logs and the policy folder
def _policies(run: Run, meta: dict[str, Any], config: dict[str, Any]) -> list[Any]:
    """The learned policy of each actor copy (one for shared parameters)."""
    from satenv.training.policy import LearnedPolicy, ObsNormalizer

    init, norm, maps = run.init_policy, ObsNormalizer(), {}
    if init is not None:   # the init policy's input and output maps stay the policy's
        norm = init.normalizer
        maps = {"features": init.features, "action_map": init.action_map, "terminal": init.terminal}
    elif run.cfg.norm_obs:
        norm = ObsNormalizer(run.norm.obs.mean, run.norm.obs.var, run.cfg.clip_obs)
    return [LearnedPolicy(export_actor(run.net, k), norm, obs_shape=(run.env_obs_dim,), meta=meta, **maps)
            for k in range(run.net.actor.copies)]


class PerAgentPolicy:
    """Per-agent learned policies behind the baseline interface (``ippo``'s evaluation)."""

    name = "learned"

    def __init__(self, policies: dict[str, Any]) -> None:
        self.policies, self.info = policies, {"fallbacks": 0}

    def reset(self, seed: int | None = None) -> None:
        self.info = {"fallbacks": 0}

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {a: self.policies[a].act({a: o})[a] for a, o in observations.items()}


def write_final(run: Run, out: Path, env: Any, wall: float) -> Path:
    """``final/``: the policy folder(s) with ``eval.json`` on the held-out test seeds."""
    from satenv.tasks import CONTROLLERS
    from satenv.training.envs import policy_env_meta
    from satenv.training.evaluate import run_summary

    cfg = run.cfg
    meta = {**policy_env_meta(cfg.env_id, env, cfg.env_kwargs, cfg.resolved_eval_env_kwargs), "step": run.steps}
    config = {**cfg.to_json(), "gamma_used": run.gamma, "trainer": "satenv.training.rl.ppo"}
    if run.init_policy is not None:
        config.update(_maps_config(run.init_policy))
    policies = _policies(run, meta, config)
    learned = (policies[0] if len(policies) == 1
               else PerAgentPolicy(dict(zip(env.possible_agents, policies, strict=True))))
    summary = run_summary(cfg, learned, reference=CONTROLLERS.get(cfg.env_id, "dmpc"), steps=run.steps,
                          train_wall_s_this_session=round(wall, 1))
    from satenv.training.policy import _jsonable, save_artifacts

    staged = runfolder.staging(out / "final")
    source = f"satenv lean PPO ({cfg.variant})"
    if len(policies) == 1:
        save_artifacts(staged, policies[0], env_meta=meta, config=config, evaluation=summary, source=source)
    else:
        for agent, policy in zip(env.possible_agents, policies, strict=True):
            save_artifacts(staged / "agents" / agent, policy, env_meta={**meta, "agent": agent}, config=config,
                           source=source)
        runfolder.write_json(staged / "eval.json", summary, indent=2, default=_jsonable)
    final = runfolder.replace_folder(staged, out / "final")
    print(f"final policy ({run.steps} agent-steps) on {len(cfg.test_seeds)} held-out seeds:\n{summary['table']}")
    return final


def _probe_seconds(run: Run, steps: int = 4) -> tuple[float, float]:
    """Seconds of one rollout step and of one minibatch update, measured by the loop's own numpy
    forward and minibatch step on throwaway copies (the run's weights, Adam moments, generators and
    env are not touched; only its work arrays are reused)."""
    from satenv.vector import SatVectorEnv

    cfg, m = run.cfg, run.vec.n_agents
    vec = SatVectorEnv(run.vec.env, cfg.num_envs, seed=cfg.seed, autoreset=True)
    obs, _ = vec.reset()
    t0 = time.perf_counter()
    for _ in range(steps):
        obs = vec.step(_actor_mean(run, _norm_obs(run, obs)))[0]
    step_s = (time.perf_counter() - t0) / steps
    rows = max(1, cfg.minibatch_size // m)
    cin = np.zeros((rows, m, run.state_dim + run.obs_dim), np.float32)
    actions, zeros = np.zeros((rows, m, run.act_dim), np.float32), np.zeros((rows, m), np.float32)
    grads = FlatArrays(run.net, np.zeros_like(run.params.buf))
    param, exp_avg, exp_avg_sq = run.params.buf.copy(), np.zeros_like(grads.buf), np.zeros_like(grads.buf)
    group = run.opt.param_groups[0]
    for k in range(4):   # the update's own minibatch step, on copies of the weights and moments
        if k == 1:       # the first: one-time costs (compiled kernels, work arrays), untimed
            t0 = time.perf_counter()
        _ppo_grad(run, grads, cin, actions, zeros, zeros, zeros)
        _clip_grad_norm(grads.buf, cfg.max_grad_norm)
        adam_step(param, grads.buf, exp_avg, exp_avg_sq, k + 1, group["lr"], group["betas"], group["eps"])
    return step_s, (time.perf_counter() - t0) / 3


class _NoBoard:
    def add_scalar(self, *args: Any) -> None:
        pass

    def close(self) -> None:
        pass


def _tensorboard(folder: Path, step: int) -> Any:
    """A TensorBoard writer of ``folder`` from ``step`` on (a no-op one, with a note, without tensorboard)."""
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError as err:
        print(f"TensorBoard logs off ({err}); progress.jsonl has the same rows", file=sys.stderr)
        return _NoBoard()
    return SummaryWriter(str(folder), purge_step=step or None)


def plan(cfg: LeanConfig, n_agents: int, done: int = 0) -> tuple[int, int]:
    """``(agent-steps per iteration, iterations)`` to reach the budget from ``done``."""
    per = cfg.num_envs * n_agents * cfg.n_steps
    return per, max(0, -(-(cfg.budget - done) // per))


# --------------------------------------------------------------------------- the loop
def train(cfg: LeanConfig, resume: bool = False) -> Path:
    """Run (or resume) a lean PPO run; returns the ``final/`` folder."""
    from satenv import tasks
    from satenv.training.envs import make_env
    from satenv.vector import SatVectorEnv

    torch.set_num_threads(cfg.torch_threads)
    out = Path(cfg.out_dir)
    found = runfolder.resume_checkpoint(out, resume, CHECKPOINT_JSON)
    ckpt = found[1] if found else None
    out.mkdir(parents=True, exist_ok=True)
    runfolder.recover_folder(out / "final")
    env = tasks.get(cfg.task).make_env(**cfg.env_kwargs) if cfg.task else make_env(cfg.env_id, **cfg.env_kwargs)
    vec = SatVectorEnv(env, cfg.num_envs, autoreset=False)
    gamma = cfg.gamma if cfg.gamma is not None else horizon_gamma(vec.max_steps, cfg.gamma_k)
    if not 0.0 < gamma < 1.0:
        raise ValueError(f"gamma_k {cfg.gamma_k} gives gamma {gamma:.4f} for max_steps {vec.max_steps}; "
                         f"gamma_k must be below max_steps (or give --gamma in (0, 1))")
    run = Run(cfg, vec, gamma)
    if ckpt is not None:
        load_checkpoint(run, ckpt)
    elif cfg.warm_start is not None:
        print(f"warm start from {warm_start(run, Path(cfg.warm_start))}", file=sys.stderr)
    runfolder.write_json(out / "config.json", {**cfg.to_json(), "gamma_used": gamma}, indent=2)
    per_iter, iterations = plan(cfg, vec.n_agents, run.steps)
    step_s, update_s = _probe_seconds(run)
    updates = cfg.n_epochs * max(1, cfg.num_envs * cfg.n_steps // max(1, cfg.minibatch_size // vec.n_agents))
    eta = iterations * (cfg.n_steps * step_s + updates * update_s)
    print(f"lean {cfg.variant} on {cfg.task or cfg.env_id}: budget {cfg.budget:,} agent-steps "
          f"({run.steps:,} done), {iterations} iterations of {per_iter:,} agent-steps "
          f"({cfg.num_envs} copies x {vec.n_agents} agents x {cfg.n_steps} steps), {updates} gradient steps "
          f"each; gamma {gamma:.4f}; expected {eta / 60:.1f} min at the measured "
          f"{per_iter / (cfg.n_steps * step_s + updates * update_s):,.0f} agent-steps/s", file=sys.stderr)
    writer = _tensorboard(out / "tb", run.steps)
    log_path = out / "progress.jsonl"
    if log_path.is_file():   # keep the lines up to the checkpoint resumed from
        kept = [ln for ln in log_path.read_text().splitlines() if ln and json.loads(ln)["agent_steps"] <= run.steps]
        runfolder.write_text(log_path, "".join(k + "\n" for k in kept))
    every = cfg.checkpoint_every or math.inf
    next_ckpt = (run.steps // every + 1) * every if cfg.checkpoint_every else math.inf
    t_start = time.perf_counter()
    for _ in range(iterations):
        timers = {"env": 0.0, "forward": 0.0, "update": 0.0}
        t0 = time.perf_counter()
        batch = collect(run, timers)
        stats = update(run, batch, timers)
        run.steps += per_iter
        wall = time.perf_counter() - t0
        fin = batch["finished"]
        if run.dual is not None:
            stats["lagrange_multiplier"] = run.dual.update(fin["cost"])
            stats["episode_cost"] = float(np.mean(fin["cost"])) if fin["cost"] else None
        row = {"agent_steps": run.steps, "episodes": len(fin["return"]),
               "return": float(np.mean(fin["return"])) if fin["return"] else None,
               "success": float(np.mean(fin["success"])) if fin["success"] else None,
               "agent_steps_per_s": per_iter / wall, "env_share": timers["env"] / wall, **stats}
        with log_path.open("a") as fh:
            fh.write(json.dumps(row) + "\n")
        for k, v in row.items():
            if v is not None and k != "agent_steps":
                writer.add_scalar(f"lean/{k}", v, run.steps)
        if run.steps >= next_ckpt:
            save_checkpoint(run, out)
            next_ckpt += cfg.checkpoint_every
    writer.close()
    wall = time.perf_counter() - t_start
    if latest_checkpoint(out) is None or latest_checkpoint(out).name != f"step_{run.steps}":
        save_checkpoint(run, out)
    return write_final(run, out, env, wall)


# --------------------------------------------------------------------------- CLI
def parser() -> argparse.ArgumentParser:
    """The command line (flags named as every trainer's: ``--task``, ``--budget``, ``--num-envs``, ...)."""
    from satenv.cliargs import new_parser

    p = new_parser("satenv ppo", __doc__.split("\n\n")[0])
    p.add_argument("--task", help="a task of satenv.tasks (its env and kwargs)")
    p.add_argument("--env-id", help="a satenv env id (default: the task's)")
    p.add_argument("--env-kwargs", type=_json_object, help="JSON object of env keyword arguments")
    p.add_argument("--variant", choices=VARIANTS)
    for name, kind in (("num-envs", int), ("n-steps", int), ("minibatch-size", int), ("n-epochs", int),
                       ("budget", int), ("seed", int), ("torch-threads", int), ("checkpoint-every", int),
                       ("lr", float), ("gamma", float), ("gamma-k", float), ("gae-lambda", float),
                       ("clip-range", float), ("ent-coef", float), ("init-std", float), ("workers", int),
                       ("lagrange-lr", float), ("cost-budget", float), ("critic-warmup", int),
                       ("target-kl", float), ("actor-lr", float)):
        p.add_argument(f"--{name}", type=kind)
    p.add_argument("--lagrangian", action="store_true", default=None,
                   help="PPO-Lagrangian on the safety_cost info at the task's cost_budget")
    for name, what in (("norm-obs", "observations"), ("norm-reward", "rewards")):
        default = "on" if getattr(LeanConfig, name.replace("-", "_")) else "off: the envs' own fixed scales"
        p.add_argument(f"--{name}", action=argparse.BooleanOptionalAction, default=None,
                       help=f"normalise the {what} by running statistics in the loop (default {default})")
    p.add_argument("--net-arch", type=lambda s: tuple(int(x) for x in s.split(",")), help="e.g. 64,64")
    p.add_argument("--test-seeds", type=_seeds, help="held-out seeds of eval.json, e.g. 900000-900019")
    p.add_argument("--eval-baselines", type=lambda s: tuple(x for x in s.split(",") if x),
                   help="scripted baselines beside the learned policy (e.g. zero,dmpc; default auto)")
    p.add_argument("--tuned", action="store_true", help="start from the task's tuned config (tuned/<task>.json)")
    p.add_argument("--warm-start", help="start the network from a lean run's folder or checkpoint "
                                        "(e.g. the run of the rung below on the task's ladder)")
    p.add_argument("--init-actor", help="start the actor from a policy folder (e.g. an imitation network), "
                                        "in its layout, features and observation normalisation")
    p.add_argument("--out-dir")
    p.add_argument("--resume", action="store_true", help="continue the run in --out-dir from its last checkpoint")
    p.add_argument("--no-progress", action="store_true", help="hide the evaluation progress bars")
    return p


def _json_object(text: str) -> dict[str, Any]:
    value = json.loads(text)
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"expected a JSON object, got {text!r:.80}")
    return value


def _seeds(text: str) -> tuple[int, ...]:
    from satenv.tasks import parse_seeds

    return parse_seeds(text)


TUNED_DIR = Path(__file__).parent / "tuned"
"""Tuned configurations per task (``<task>.json``: fields of :class:`LeanConfig`), chosen on
validation seeds."""


def tuned_path(task: str) -> Path:
    """Where ``task``'s committed tuned configuration lives (``satenv ppo-tune --update-published``)."""
    return TUNED_DIR / f"{task}.json"


def tuned(task: str) -> dict[str, Any]:
    """The tuned fields of ``task`` (``{}`` when none is committed)."""
    path = tuned_path(task)
    return json.loads(path.read_text())["config"] if path.is_file() else {}


def config_from_args(argv: list[str] | None) -> tuple[LeanConfig, bool]:
    """``(config, resume)`` of a command line; a bad value is an error naming its flag."""
    from satenv.cliargs import flag_message

    args = parser().parse_args(argv)
    given = {k: v for k, v in vars(args).items() if v is not None and k not in ("resume", "tuned", "no_progress")}
    if args.no_progress:
        given["progress"] = False
    try:
        if args.resume and runfolder.resumable(given.get("out_dir", LeanConfig.out_dir)):
            saved = runfolder.read_json(Path(given.get("out_dir", LeanConfig.out_dir)) / "config.json",
                                        "the run's config")
            saved.pop("gamma_used", None)
            return config_from_json({**saved, **given}, LeanConfig), True
        if args.tuned:
            given = {**tuned(given.get("task") or LeanConfig(**given).task), **given}
        return LeanConfig(**given), args.resume
    except (ValueError, TypeError) as err:
        raise type(err)(flag_message(LeanConfig, str(err))) from None


def main(argv: list[str] | None = None) -> int:
    """``satenv ppo``: parse, train, print where the policy is; 0 on success, 2 on a bad input."""
    try:
        cfg, resume = config_from_args(argv)
        final = train(cfg, resume=resume)
    except ValueError as err:   # satenv's input errors and RunFolderError are ValueErrors
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"policy folder: {final}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
