"""A single-agent, centralised Gymnasium view of a satenv scenario.

:class:`CentralisedEnv` wraps one PettingZoo env (the dict path, ``B = 1``): the observation is
the concatenation of every agent's observation (agent order of ``possible_agents``), the action
the concatenation of every agent's normalised action, the reward the team sum (or mean) of the
agents' rewards. Terminated/truncated follow the team. It passes
``gymnasium.utils.env_checker.check_env`` and serves single-agent algorithms and SB3's
``DummyVecEnv`` (the per-copy baseline of ``python -m benchmarks.perf --sections training``).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from satenv.envs.base import FormationEnv, SatenvError
from training.vec_env import make_env

__all__ = ["CentralisedEnv"]


class CentralisedEnv(gym.Env):
    """One controller for all agents of a satenv env.

    Args:
        env: a :class:`FormationEnv` instance, or an env id (``"platoon_v0"``) built with ``env_kwargs``.
        reward: ``"sum"`` (default) or ``"mean"`` of the agents' rewards.
        env_kwargs: keyword arguments when ``env`` is an id.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, env: FormationEnv | str = "platoon_v0", *, reward: str = "sum",
                 render_mode: str | None = None, **env_kwargs: Any) -> None:
        if reward not in ("sum", "mean"):
            raise SatenvError(f"reward must be 'sum' or 'mean', got {reward!r}")
        if isinstance(env, str):
            env = make_env(env, render_mode=render_mode, **env_kwargs)
        elif env_kwargs:
            raise SatenvError(f"env_kwargs {sorted(env_kwargs)} given with an env instance; pass an env id instead")
        if not isinstance(env, FormationEnv):
            raise SatenvError(f"CentralisedEnv needs a satenv FormationEnv or an env id, got {type(env).__name__}")
        self.env = env
        self.render_mode = env.render_mode
        self.agents = list(env.possible_agents)
        self._reduce = np.sum if reward == "sum" else np.mean
        o = env.observation_space(self.agents[0])
        a = env.action_space(self.agents[0])
        m = len(self.agents)
        self.obs_dim, self.act_dim = int(o.shape[0]), int(a.shape[0])
        self.observation_space = spaces.Box(-np.inf, np.inf, (m * self.obs_dim,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (m * self.act_dim,), np.float32)

    def _flat(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        return np.concatenate([obs[a] for a in self.agents]).astype(np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        obs, infos = self.env.reset(seed=seed, options=options)
        return self._flat(obs), {"agents": infos}

    def step(self, action: np.ndarray):
        a = np.asarray(action, dtype=np.float64)
        if a.shape != self.action_space.shape:
            raise SatenvError(f"action must have shape {self.action_space.shape} "
                              f"({len(self.agents)} agents x {self.act_dim}), got {a.shape}")
        split = a.reshape(len(self.agents), self.act_dim)
        obs, rew, term, trunc, infos = self.env.step({ag: split[i] for i, ag in enumerate(self.agents)})
        reward = float(self._reduce([rew[ag] for ag in self.agents]))
        return self._flat(obs), reward, any(term.values()), any(trunc.values()), {"agents": infos}

    def render(self):
        return self.env.render()

    def close(self) -> None:
        self.env.close()
