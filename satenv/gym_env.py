"""A single-agent, centralised Gymnasium view of a satenv scenario.

:class:`CentralisedEnv` wraps one PettingZoo env (the dict path, ``B = 1``): the observation is
the concatenation of every agent's observation (agent order of ``possible_agents``), the action
the concatenation of every agent's normalised action, the reward the team sum (or mean) of the
agents' rewards. Terminated/truncated follow the team. It passes
``gymnasium.utils.env_checker.check_env`` and serves single-agent algorithms.

``import satenv`` registers it with Gymnasium for every env (``satenv.GYM_IDS``)::

    import gymnasium as gym
    import satenv

    env = gym.make("satenv/Platoon-v0", topology="BDL", max_steps=100)   # env kwargs as in satenv.make
    vec = gym.make_vec("satenv/Platoon-v0", num_envs=64)    # one batched core (satenv.gym_vector)

Episode length: the env truncates at its own ``max_steps`` (the preset's, or the ``max_steps=``
given), so ``gymnasium.make("satenv/Platoon-v0", max_steps=500)`` runs 500 steps; the registered
ids add no ``TimeLimit`` of their own and ``env.spec.max_episode_steps`` reports that
``max_steps``. ``gymnasium.make(..., max_episode_steps=n)`` still adds a ``TimeLimit`` of ``n``.
``render_mode`` is checked by the env (a :class:`~satenv.errors.SatenvError` naming it, e.g. for
``render_mode=3``); ``"rgb_array_list"`` gives Gymnasium's ``RenderCollection``. ``render()``
without a ``render_mode`` warns and returns ``None``.
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from satenv.envs.base import SatenvError, SatParallelEnv

__all__ = ["CentralisedEnv", "make_centralised"]


class CentralisedEnv(gym.Env):
    """One controller for all agents of a satenv env.

    Args:
        env: a :class:`~satenv.envs.base.SatParallelEnv` instance, or an env id (``"platoon_v0"``,
            one of ``satenv.ENV_IDS``) built with ``satenv.make(env, **env_kwargs)``.
        team_reward: ``"sum"`` (default) or ``"mean"`` of the agents' rewards (the agents' own
            reward is the env's ``reward=`` keyword, ``"paper"`` or ``"training"``: an env kwarg).
        render_mode: passed to the env when ``env`` is an id.
        env_kwargs: keyword arguments of the env when ``env`` is an id.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    def __init__(self, env: SatParallelEnv | str = "platoon_v0", *, team_reward: str = "sum",
                 render_mode: str | None = None, **env_kwargs: Any) -> None:
        if team_reward not in ("sum", "mean"):
            raise SatenvError(f"team_reward must be 'sum' or 'mean', got {team_reward!r:.40}")
        if isinstance(env, str):
            from satenv import make

            env = make(env, render_mode=render_mode, **env_kwargs)
        elif env_kwargs:
            raise SatenvError(f"env_kwargs {sorted(env_kwargs)} given with an env instance; pass an env id instead")
        if not isinstance(getattr(env, "unwrapped", env), SatParallelEnv):   # a wrapper (satenv.safety) too
            raise SatenvError(f"CentralisedEnv needs a satenv SatParallelEnv or an env id, got {type(env).__name__}")
        self.env = env
        self.render_mode = env.render_mode
        self.metadata = {**self.metadata, "render_fps": env.metadata["render_fps"]}
        self.agents = list(env.possible_agents)
        self._reduce = np.sum if team_reward == "sum" else np.mean
        o = env.observation_space(self.agents[0])
        a = env.action_space(self.agents[0])
        m = len(self.agents)
        self.obs_dim, self.act_dim = int(o.shape[0]), int(a.shape[0])
        self.observation_space = spaces.Box(-np.inf, np.inf, (m * self.obs_dim,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (m * self.act_dim,), np.float32)

    @property
    def spec(self) -> Any:
        """The ``EnvSpec`` ``gymnasium.make`` gave this env, with ``max_episode_steps`` the env's own
        ``max_steps`` (where it truncates) when the spec gives none."""
        return self.__dict__.get("_spec")

    @spec.setter
    def spec(self, value: Any) -> None:
        if value is not None and getattr(value, "max_episode_steps", 0) is None:
            value = dataclasses.replace(value, max_episode_steps=int(self.env.scenario.max_steps))
        self.__dict__["_spec"] = value

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
        if self.render_mode is None:
            warnings.warn("render() without a render mode draws nothing: make the env with "
                          "render_mode='rgb_array' (frames) or 'human' (a window), e.g. "
                          "gymnasium.make('satenv/Platoon-v0', render_mode='rgb_array')", UserWarning, stacklevel=2)
            return None
        return self.env.render()

    def close(self) -> None:
        self.env.close()


LIST_SUFFIX = "_list"
"""A ``render_mode`` ending in it (``"rgb_array_list"``) collects frames (Gymnasium's convention)."""


def make_centralised(env: str = "platoon_v0", *, render_mode: Any = None, **kwargs: Any) -> gym.Env:
    """The registered entry point of ``satenv.GYM_IDS``: a :class:`CentralisedEnv`.

    A function without ``metadata``, so that ``gymnasium.make`` hands ``render_mode`` to the env's
    own check (a typed error naming it, whatever its type) instead of testing it itself;
    ``"rgb_array_list"`` is ``"rgb_array"`` inside Gymnasium's ``RenderCollection``, as
    ``gymnasium.make`` does for an env that declares its modes.
    """
    collect = isinstance(render_mode, str) and render_mode.endswith(LIST_SUFFIX) \
        and render_mode[:-len(LIST_SUFFIX)] in CentralisedEnv.metadata["render_modes"]
    base = CentralisedEnv(env, render_mode=render_mode[:-len(LIST_SUFFIX)] if collect else render_mode, **kwargs)
    if collect:
        from gymnasium.wrappers import RenderCollection

        return RenderCollection(base)
    return base
