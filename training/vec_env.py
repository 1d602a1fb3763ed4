"""Stable-Baselines3 ``VecEnv`` over a satenv batched core, with parameter sharing.

:class:`SatVecEnv` runs ``B`` copies of one scenario in ONE :class:`satenv.envs.base.BatchedCore`
(``batch=B``) and exposes every agent of every copy as one row of the SB3 batch, so
``num_envs = B * M`` and a single shared policy controls all agents. Row ``r`` is agent
``r % M`` of copy ``r // M``. One ``step`` is one batched ``core.step`` call — no Python loop over
copies on the stepping path.

Semantics (matching :class:`satenv.envs.base.SatParallelEnv`):

* actions in ``[-1, 1]^action_dim`` are scaled with :func:`satenv.dynamics.unit_box_to_accel`
  using ``scenario.u_max`` and ``scenario.thrust_mode``, exactly as ``SatParallelEnv.step`` does;
* a copy ends when the core reports termination (team termination: every agent of the copy is
  ``done``) or when its step counter reaches ``scenario.max_steps`` (truncation, flagged with
  ``info["TimeLimit.truncated"] = True`` so SB3 bootstraps);
* finished copies are reset in the same ``step`` through ``core.reset(x0, idx)``; the returned
  observation is then the first one of the new episode and the last one of the finished episode
  is in ``info["terminal_observation"]`` (the SB3 convention);
* seeding: ``seed(s)`` (or the ``seed`` argument) takes effect at the next ``reset()``. Copy
  ``b`` owns a generator seeded with ``s + b`` that draws its initial states, so the first
  episode of copy ``b`` starts exactly where ``env.reset(seed=s + b)`` of the PettingZoo env
  starts; stochastic physics inside ``core.step`` draws from one batch generator seeded from
  ``s``.

The raw physical info arrays of the last step (``(B, M, ...)``, the ``INFO_KEYS`` of
``satenv.envs.base``) are kept in :attr:`SatVecEnv.last_info` (the per-row ``infos`` list carries
only the SB3 keys, to keep the step cheap).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

import satenv
from satenv.dynamics import unit_box_to_accel
from satenv.envs.base import SatenvError, SatParallelEnv

__all__ = ["SatVecEnv", "make_env", "env_version"]


def make_env(env_id: str, **kwargs: Any) -> SatParallelEnv:
    """Build the PettingZoo env ``env_id`` with ``kwargs``.

    ``env_id`` is a satenv env id (``satenv.ENV_IDS``, built with ``satenv.make``) or
    ``"package.module:callable"`` for an env defined elsewhere (e.g. a test fixture).
    """
    if not isinstance(env_id, str) or not env_id:
        raise SatenvError(f"env_id must be a non-empty string such as 'platoon_v0', got {env_id!r}")
    if ":" not in env_id:
        if env_id not in satenv.ENV_IDS:
            raise SatenvError(f"unknown env id {env_id!r}: use one of {list(satenv.ENV_IDS)} or "
                              "'package.module:callable'")
        return satenv.make(env_id, **kwargs)
    module_name, _, attr = env_id.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as err:
        raise SatenvError(f"unknown env id {env_id!r}: cannot import {module_name!r} ({err}); use a "
                          "satenv env name such as 'platoon_v0' or 'package.module:callable'") from None
    factory = getattr(module, attr, None)
    if factory is None:
        raise SatenvError(f"unknown env id {env_id!r}: {module_name!r} has no attribute {attr!r}")
    env = factory(**kwargs)
    if not isinstance(env, SatParallelEnv):
        raise SatenvError(f"env id {env_id!r} built a {type(env).__name__}; expected a "
                          "satenv.envs.base.SatParallelEnv subclass (it needs a batched core)")
    return env


def env_version(env_id: str) -> str:
    """The version suffix of an env id (``"platoon_v0"`` -> ``"v0"``), or ``""``."""
    tail = env_id.rsplit(":", 1)[-1].rsplit("_", 1)
    return tail[-1] if len(tail) == 2 and tail[-1].startswith("v") else ""


class SatVecEnv(VecEnv):
    """``n_copies`` copies of a satenv scenario as one parameter-shared SB3 ``VecEnv``.

    Args:
        env: a :class:`SatParallelEnv` instance (only its class, scenario and spaces are used; it
            is not stepped), or a zero-argument callable returning one.
        n_copies: number of scenario copies ``B`` (>= 1); ``num_envs = B * n_agents``.
        seed: optional seed applied at the first ``reset()`` (see the module docstring).
        reward_fn: optional training-time shaping ``(rewards (B, M), info) -> rewards (B, M)``
            (e.g. :class:`training.shaping.RewardShaping`).
        obs_fn: optional feature map applied to the observations ``(..., obs_dim) -> (..., d)``
            (e.g. :class:`training.shaping.ObsFeatures`); the observation space follows.
        action_fn: optional map of the policy's actions in ``[-1, 1]`` to env actions in
            ``[-1, 1]`` (e.g. :class:`training.shaping.ActionMap`), applied before the scaling.
    """

    def __init__(self, env: SatParallelEnv | Callable[[], SatParallelEnv], n_copies: int,
                 seed: int | None = None, *,
                 reward_fn: Callable[[np.ndarray, dict[str, np.ndarray]], np.ndarray] | None = None,
                 obs_fn: Callable[[np.ndarray], np.ndarray] | None = None,
                 action_fn: Callable[[np.ndarray], np.ndarray] | None = None) -> None:
        template = env() if callable(env) and not isinstance(env, SatParallelEnv) else env
        if not isinstance(template, SatParallelEnv):
            raise SatenvError(f"SatVecEnv needs a satenv SatParallelEnv (or a callable returning one), "
                              f"got {type(template).__name__}")
        if isinstance(n_copies, bool) or not isinstance(n_copies, (int, np.integer)) or n_copies < 1:
            raise SatenvError(f"n_copies must be a positive int, got {n_copies!r}")
        self.template = template
        self.scenario = template.scenario
        self.n_copies = int(n_copies)
        self.core = template.core_class(self.scenario, batch=self.n_copies)
        self.n_agents = self.core.n_agents
        self.agents = list(template.possible_agents)
        self.max_steps = int(self.scenario.max_steps)
        self.render_mode = None
        agent = self.agents[0]
        obs_space = template.observation_space(agent)
        self.reward_fn, self.obs_fn, self.action_fn = reward_fn, obs_fn, action_fn
        if obs_fn is not None:
            dim = np.asarray(obs_fn(np.zeros((1, *obs_space.shape), dtype=np.float32))).shape[-1]
            obs_space = spaces.Box(-np.inf, np.inf, (int(dim),), np.float32)
        super().__init__(self.n_copies * self.n_agents, obs_space, template.action_space(agent))
        self._u_max = self.scenario.u_max
        self._thrust_mode = self.scenario.thrust_mode
        self._copy_rngs: list[np.random.Generator] = []
        self._batch_rng = np.random.default_rng()
        self._pending_seed: int | None = None
        self._actions: np.ndarray | None = None
        self._obs_shape = (self.num_envs, *self.observation_space.shape)
        self.last_info: dict[str, np.ndarray] = {}
        self.episode_count = 0
        if seed is not None:
            self.seed(seed)

    # ------------------------------------------------------------------ seeding
    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seed the next ``reset()``: copy ``b`` uses ``seed + b``; returns the seed of every row."""
        if seed is None:
            seed = int(np.random.SeedSequence().generate_state(1)[0])
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise SatenvError(f"seed must be a non-negative int or None, got {seed!r}")
        self._pending_seed = int(seed)
        return [int(seed) + r // self.n_agents for r in range(self.num_envs)]

    def _apply_seed(self) -> None:
        seed = self._pending_seed
        self._pending_seed = None
        if seed is None:
            if not self._copy_rngs:  # never seeded: fresh entropy
                ss = np.random.SeedSequence()
                self._copy_rngs = [np.random.default_rng(s) for s in ss.spawn(self.n_copies)]
            return
        self._copy_rngs = [np.random.default_rng(seed + b) for b in range(self.n_copies)]
        # the batch generator for in-step randomness: independent stream derived from `seed`
        self._batch_rng = np.random.default_rng(np.random.SeedSequence([seed, self.n_copies, 7919]))

    def _sample(self, idx: np.ndarray) -> np.ndarray:
        return np.concatenate([self.core.sample_initial_state(self._copy_rngs[b], 1) for b in idx])

    # ----------------------------------------------------------------- VecEnv API
    def reset(self) -> np.ndarray:
        """Reset every copy (applying a pending seed); returns observations ``(B*M, obs_dim)``."""
        self._apply_seed()
        idx = np.arange(self.n_copies)
        self.last_info = self.core.reset(self._sample(idx), None, self._batch_rng)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._reset_options()
        return self._observe()

    def _observe(self) -> np.ndarray:
        obs = np.asarray(self.core.observe(), dtype=np.float32)
        if self.obs_fn is not None:
            obs = np.asarray(self.obs_fn(obs), dtype=np.float32)
        return obs.reshape(self._obs_shape)

    def step_async(self, actions: np.ndarray) -> None:
        a = np.asarray(actions, dtype=np.float64)
        expected = (self.num_envs, *self.action_space.shape)
        if a.shape != expected:
            if a.size == np.prod(expected):
                a = a.reshape(expected)
            else:
                raise SatenvError(f"actions must have shape {expected} (one row per agent of every "
                                  f"copy), got {a.shape}")
        self._actions = a

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise SatenvError("step_wait() called without step_async(): call step(actions)")
        if not self._copy_rngs:
            raise SatenvError("step() called before reset(): call reset() first")
        a = self._actions.reshape(self.n_copies, self.n_agents, -1)
        self._actions = None
        if self.action_fn is not None:
            a = self.action_fn(a)
        accel = unit_box_to_accel(a, self._u_max, self._thrust_mode)
        res = self.core.step(accel, self._batch_rng)
        self.last_info = res.info
        terminated = np.asarray(res.terminated, dtype=bool)
        truncated = (self.core.t >= self.max_steps) & ~terminated
        done_copy = terminated | truncated
        obs = self._observe()
        rewards = res.rewards if self.reward_fn is None else self.reward_fn(res.rewards, res.info)
        rewards = np.asarray(rewards, dtype=np.float32).reshape(self.num_envs)
        dones = np.repeat(done_copy, self.n_agents)
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if done_copy.any():
            idx = np.flatnonzero(done_copy)
            self.episode_count += len(idx)
            for b in idx:
                for m in range(self.n_agents):
                    r = b * self.n_agents + m
                    infos[r]["terminal_observation"] = obs[r].copy()
                    infos[r]["TimeLimit.truncated"] = bool(truncated[b])
            self.core.reset(self._sample(idx), idx, self._batch_rng)
            obs = self._observe()
        return obs, rewards, dones, infos

    def close(self) -> None:
        self.template.close()

    # ------------------------------------------------------ attribute plumbing
    def _indices(self, indices: VecEnvIndices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The template env's attribute (the same for every row)."""
        if attr_name == "render_mode":
            value = None
        else:
            value = getattr(self.template, attr_name)
        return [value for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise SatenvError(f"SatVecEnv shares one core between all rows; cannot set {attr_name!r} per env")

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None,
                   **method_kwargs) -> list[Any]:
        raise SatenvError(f"SatVecEnv has no per-row env objects; cannot call {method_name!r}")

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        raise SatenvError("SatVecEnv does not render; use the PettingZoo env with render_mode='rgb_array'")

    def __repr__(self) -> str:
        name = self.template.metadata.get("name", type(self.template).__name__)
        return f"SatVecEnv({name}, n_copies={self.n_copies}, n_agents={self.n_agents})"

