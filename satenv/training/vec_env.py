"""Stable-Baselines3 ``VecEnv`` over :func:`satenv.make_vec`, with parameter sharing.

:class:`SatVecEnv` is a thin adapter over :class:`satenv.vector.SatVectorEnv` (``B`` copies of
one scenario in one batched core; its docstring has the semantics: action scaling, team
termination, truncation at ``scenario.max_steps``, same-step auto-reset, per-copy seeding). It
exposes every agent of every copy as one row of the SB3 batch, so ``num_envs = B * M`` and a
single shared policy controls all agents. Row ``r`` is agent ``r % M`` of copy ``r // M``.

SB3 conventions added here: a truncated copy's rows get ``info["TimeLimit.truncated"] = True``
(so SB3 bootstraps) and the last observation of a finished episode is in
``info["terminal_observation"]``; ``seed(s)`` takes effect at the next ``reset()`` (copy ``b``
then reproduces the PettingZoo env's ``reset(seed=s + b)``). The raw physical info arrays of the
last step (``(B, M, ...)``, before any auto-reset) are in :attr:`SatVecEnv.last_info` (the per-row
``infos`` list carries only the SB3 keys, to keep the step cheap).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

from satenv.envs.base import SatenvError, SatParallelEnv
from satenv.training.envs import env_version, make_env
from satenv.vector import SatVectorEnv, check_seed

__all__ = ["SatVecEnv", "make_env", "env_version"]


class SatVecEnv(VecEnv):
    """``n_copies`` copies of a satenv scenario as one parameter-shared SB3 ``VecEnv``.

    Args:
        env: a :class:`SatParallelEnv` instance (only its class, scenario and spaces are used; it
            is not stepped), or a zero-argument callable returning one.
        n_copies: number of scenario copies ``B`` (>= 1); ``num_envs = B * n_agents``.
        seed: optional seed applied at the first ``reset()`` (see the module docstring).
        reward_fn: optional training-time shaping ``(rewards (B, M), info) -> rewards (B, M)``
            (e.g. :class:`satenv.training.shaping.RewardShaping`).
        obs_fn: optional feature map applied to the observations ``(..., obs_dim) -> (..., d)``
            (e.g. :class:`satenv.training.shaping.ObsFeatures`); the observation space follows.
        action_fn: optional map of the policy's actions in ``[-1, 1]`` to env actions in
            ``[-1, 1]`` (e.g. :class:`satenv.training.shaping.ActionMap`), applied before the scaling.
    """

    def __init__(self, env: SatParallelEnv | Callable[[], SatParallelEnv], n_copies: int,
                 seed: int | None = None, *,
                 reward_fn: Callable[[np.ndarray, dict[str, np.ndarray]], np.ndarray] | None = None,
                 obs_fn: Callable[[np.ndarray], np.ndarray] | None = None,
                 action_fn: Callable[[np.ndarray], np.ndarray] | None = None) -> None:
        template = env() if callable(env) and not isinstance(env, SatParallelEnv) else env
        if not isinstance(getattr(template, "unwrapped", template), SatParallelEnv):
            raise SatenvError(f"SatVecEnv needs a satenv SatParallelEnv (or a callable returning one), "
                              f"got {type(template).__name__}")
        if isinstance(n_copies, bool) or not isinstance(n_copies, (int, np.integer)) or n_copies < 1:
            raise SatenvError(f"n_copies must be a positive int, got {n_copies!r}")
        self.template = template
        self.vec = SatVectorEnv(template, int(n_copies), seed=seed)
        self.scenario, self.core = self.vec.scenario, self.vec.core
        self.n_copies, self.n_agents = self.vec.num_envs, self.vec.n_agents
        self.agents = self.vec.agents
        self.render_mode = None
        obs_space = self.vec.single_observation_space
        self.reward_fn, self.obs_fn, self.action_fn = reward_fn, obs_fn, action_fn
        if obs_fn is not None:
            dim = np.asarray(obs_fn(np.zeros((1, *obs_space.shape), dtype=np.float32))).shape[-1]
            obs_space = spaces.Box(-np.inf, np.inf, (int(dim),), np.float32)
        super().__init__(self.n_copies * self.n_agents, obs_space, self.vec.single_action_space)
        self._pending_seed: int | None = None
        self._actions: np.ndarray | None = None
        self._obs_shape = (self.num_envs, *self.observation_space.shape)
        self.last_info: dict[str, np.ndarray] = {}
        self.episode_count = 0

    # ------------------------------------------------------------------ seeding
    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seed the next ``reset()``: copy ``b`` uses ``seed + b``; returns the seed of every row."""
        if seed is None:
            seed = int(np.random.SeedSequence().generate_state(1)[0])
        self._pending_seed = check_seed(seed)
        return [int(seed) + r // self.n_agents for r in range(self.num_envs)]

    # ----------------------------------------------------------------- VecEnv API
    def reset(self) -> np.ndarray:
        """Reset every copy (applying a pending seed); returns observations ``(B*M, obs_dim)``."""
        obs, self.last_info = self.vec.reset(seed=self._pending_seed)
        self._pending_seed = None
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._reset_options()
        return self._rows(obs)

    def _rows(self, obs: np.ndarray) -> np.ndarray:
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
        a = self._actions.reshape(self.n_copies, self.n_agents, -1)
        self._actions = None
        if self.action_fn is not None:
            a = self.action_fn(a)
        obs, rewards, term, trunc, infos = self.vec.step(a)
        final = infos.get("_final_obs")
        self.last_info = infos["final_info"] if final is not None else infos
        if self.reward_fn is not None:
            rewards = self.reward_fn(rewards, self.last_info)
        rewards = np.asarray(rewards, dtype=np.float32).reshape(self.num_envs)
        row_infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if final is not None:
            last = self._rows(infos["final_obs"])
            idx = np.flatnonzero(final)
            self.episode_count += len(idx)
            for b in idx:
                for m in range(self.n_agents):
                    r = b * self.n_agents + m
                    row_infos[r]["terminal_observation"] = last[r]
                    row_infos[r]["TimeLimit.truncated"] = bool(trunc[b, 0])
        dones = (term | trunc).reshape(self.num_envs)
        return self._rows(obs), rewards, dones, row_infos

    def close(self) -> None:
        self.vec.close()

    # ------------------------------------------------------------------ state (resume)
    def get_state(self) -> dict[str, np.ndarray]:
        """The episodes in flight (:meth:`satenv.vector.SatVectorEnv.get_state`: the core, the
        generators, the training reward's memory); with :meth:`set_state` a checkpoint resumes
        them bit for bit."""
        return self.vec.get_state()

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore :meth:`get_state` (:meth:`satenv.vector.SatVectorEnv.set_state`)."""
        self.vec.set_state(state)

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

