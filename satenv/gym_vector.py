"""The centralised Gymnasium view of :mod:`satenv.gym_env`, vectorised over the batched core.

``gymnasium.make_vec("satenv/Platoon-v0", num_envs=64)`` returns a
:class:`CentralisedVectorEnv` (the registered ``vector_entry_point``): ``num_envs`` copies of the
scenario in ONE batched numpy core (:class:`satenv.vector.SatVectorEnv`), not 64 Python envs.
Per copy it is :class:`satenv.gym_env.CentralisedEnv`: the observation is every agent's
observation concatenated (agent order of ``possible_agents``), the action every agent's
normalised action concatenated, the reward the team sum (or mean), terminated/truncated the team's.

Gymnasium 1.x conventions: ``metadata["autoreset_mode"]`` is ``AutoresetMode.SAME_STEP`` (a copy
that ends is reset inside the same ``step``; the returned observation is the new episode's first,
``infos["final_obs"]`` (an object array, the finished episode's last observation where
``infos["_final_obs"]`` is true) and ``infos["final_info"]`` / ``infos["_final_info"]`` hold the
last step). The other ``infos`` entries are the env's per-agent physical quantities as
``(num_envs, n_agents, ...)`` arrays. ``reset(seed=s)`` seeds copy ``b`` with ``s + b``, as
``gymnasium.make("satenv/Platoon-v0").reset(seed=s + b)``.

Each copy truncates at the scenario's ``max_steps`` (``max_steps=`` sets it); a
``max_episode_steps`` given to ``gymnasium.make_vec`` caps it further (the registered ids give none).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from satenv.errors import SatenvError
from satenv.vector import FINAL_ALIASES

FINAL_KEYS = ("final_obs", "_final_obs", "final_info", "_final_info")
"""The batched core's auto-reset keys, rebuilt here per Gymnasium (``final_obs`` an object array)."""

__all__ = ["CentralisedVectorEnv"]


class CentralisedVectorEnv(VectorEnv):
    """``num_envs`` copies of ``satenv.make(env, **env_kwargs)`` as one Gymnasium ``VectorEnv``.

    Args:
        env: a satenv env id (one of ``satenv.ENV_IDS``).
        num_envs: copies in the batched core (>= 1).
        team_reward: ``"sum"`` (default) or ``"mean"`` of the agents' rewards (the agents' own
            reward is the env's ``reward=`` keyword, ``"paper"`` or ``"training"``: an env kwarg).
        max_episode_steps: episode length cap (module docstring); ``None``: the scenario's.
        render_mode: must be ``None`` (render one copy with the PettingZoo env instead).
        env_kwargs: keyword arguments of the env, as for ``satenv.make``.
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, env: str = "platoon_v0", num_envs: int = 1, *, team_reward: str = "sum",
                 max_episode_steps: int | None = None, render_mode: str | None = None,
                 **env_kwargs: Any) -> None:
        import satenv
        from satenv.vector import SatVectorEnv

        if team_reward not in ("sum", "mean"):
            raise SatenvError(f"team_reward must be 'sum' or 'mean', got {team_reward!r:.40}")
        if render_mode is not None:
            raise SatenvError(f"render_mode={render_mode!r}: the vector env does not render; render one "
                              "copy with satenv.make(env_id, render_mode=...) or gymnasium.make")
        template = satenv.make(env, **env_kwargs)
        if max_episode_steps is not None and max_episode_steps < template.scenario.max_steps:
            template = satenv.make(env, **{**env_kwargs, "max_steps": int(max_episode_steps)})
        self.vec = SatVectorEnv(template, num_envs)
        self.num_envs = self.vec.num_envs
        self.render_mode = None
        self._reduce = np.sum if team_reward == "sum" else np.mean
        m = self.vec.n_agents
        od, ad = self.vec.single_observation_space.shape[0], self.vec.single_action_space.shape[0]
        self._act_shape = (self.num_envs, m, ad)
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (m * od,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (m * ad,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.metadata = {**self.metadata, "name": template.metadata.get("name")}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if options:
            raise SatenvError(f"reset options {sorted(options)} are not supported by the vector env")
        obs, infos = self.vec.reset(seed=seed)
        return self._flat(obs), dict(infos)

    def step(self, actions: Any):
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != self.action_space.shape:
            raise SatenvError(f"actions must have shape {self.action_space.shape} (num_envs x agents*act_dim), "
                              f"got {a.shape}")
        obs, rew, term, trunc, infos = self.vec.step(a.reshape(self._act_shape))
        out = {k: v for k, v in infos.items() if k not in (*FINAL_KEYS, *FINAL_ALIASES)}
        if "_final_obs" in infos:
            mask = np.asarray(infos["_final_obs"], dtype=bool)
            last = self._flat(infos["final_obs"])
            final_obs = np.full(self.num_envs, None, dtype=object)
            for b in np.flatnonzero(mask):
                final_obs[b] = last[b]
            out.update(final_obs=final_obs, _final_obs=mask, final_info=infos["final_info"], _final_info=mask.copy())
        return (self._flat(obs), self._reduce(rew, axis=1).astype(np.float64), term.any(axis=1),
                trunc.any(axis=1), out)

    def _flat(self, obs: np.ndarray) -> np.ndarray:
        return np.asarray(obs, dtype=np.float32).reshape(self.num_envs, -1)

    def render(self):
        warnings.warn("CentralisedVectorEnv.render(): the vector env does not render; render one copy with "
                      "satenv.make(env_id, render_mode='rgb_array') or gymnasium.make(..., render_mode=...)",
                      UserWarning, stacklevel=2)

    def close_extras(self, **kwargs: Any) -> None:
        if hasattr(self, "vec"):
            self.vec.close()
