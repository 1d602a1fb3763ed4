"""Native TorchRL env over :func:`satenv.make_vec` (needs the ``marl`` extra: torchrl, tensordict).

    from satenv.torchrl import make_env
    env = make_env("platoon_v0", num_envs=64, seed=0)      # EnvBase, batch_size=(64,)
    td = env.rollout(100)                                  # random actions

One agent group ``"agents"`` (VMAS/BenchMARL layout), arrays ``(B, M, ...)`` for ``B`` copies
and ``M`` agents:

* ``("agents", "observation")`` float32 ``(B, M, obs_dim)``; ``"state"`` float32 ``(B, state_dim)``
  (the PettingZoo env's ``state()``, for centralised critics);
* ``("agents", "action")`` in ``[-1, 1]`` ``(B, M, act_dim)``;
* ``("agents", "reward")`` float32 ``(B, M, 1)`` (the env's ``reward=``: ``"paper"`` or
  ``"training"``, :mod:`satenv.rewards`);
* ``("agents", "safety_cost")`` float32 ``(B, M, 1)``: 1 on a collision or a hard-bound violation
  of the agent in the step, else 0 (:func:`satenv.rewards.safety_cost`; 0 at reset), for
  constrained RL against the task's ``cost_budget``;
* ``done``/``terminated``/``truncated`` bool, per copy ``(B, 1)`` and per agent
  ``("agents", "done")`` etc. ``(B, M, 1)`` (termination is team-wide, so they agree).

Finished copies are reset by TorchRL through ``"_reset"`` (``SatVectorEnv(autoreset=False)``).
Seeding: ``make_env(..., seed=s)`` or ``env.set_seed(s)`` gives copy ``b`` the PettingZoo env's
``reset(seed=s + b)`` episodes. Stepping is the batched numpy core: no Python loop over copies.
Note: importing torchrl sets the process's ``multiprocessing`` start method to ``"spawn"``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from satenv.errors import SatenvError
from satenv.vector import SatVectorEnv

__all__ = ["SatTorchRLEnv", "make_env"]


def make_env(env_id: str, num_envs: int, *, device: str | torch.device = "cpu", seed: int | None = None,
             safety_filter: Any = False, **env_kwargs: Any) -> SatTorchRLEnv:
    """``num_envs`` copies of ``satenv.make(env_id, **env_kwargs)`` as a TorchRL ``EnvBase``;
    ``safety_filter=True`` (or a ``SafetyConfig``) filters the actions (:mod:`satenv.safety`) and
    adds ``("agents", "safety_intervened")`` / ``("agents", "safety_delta")`` ``(B, M, 1)``."""
    import satenv

    vec = SatVectorEnv(satenv.make(env_id, safety_filter=safety_filter, **env_kwargs), num_envs, seed=seed,
                       autoreset=False)
    return SatTorchRLEnv(vec, device=device)


class SatTorchRLEnv(EnvBase):
    """A :class:`satenv.vector.SatVectorEnv` (``autoreset=False``) as a batched TorchRL env."""

    def __init__(self, vec: SatVectorEnv, *, device: str | torch.device = "cpu") -> None:
        if not isinstance(vec, SatVectorEnv) or vec.autoreset:
            raise TypeError("SatTorchRLEnv needs a SatVectorEnv built with autoreset=False; use make_env(...)")
        given = device
        try:  # a device this torch build has, named in the error otherwise (e.g. 'cuda:7' on CPU)
            device = torch.device(device)
            torch.zeros(1, device=device).cpu()  # holds data ('meta' does not)
        except (AssertionError, NotImplementedError, RuntimeError, TypeError, ValueError) as exc:
            raise SatenvError(f"device must be a torch device available here (e.g. 'cpu'), got {given!r:.40} "
                              f"({type(exc).__name__}: {str(exc).splitlines()[0][:80]})") from None
        super().__init__(device=device, batch_size=torch.Size([vec.num_envs]))
        self.vec = vec
        self.group_map = {"agents": list(vec.agents)}
        b, m = vec.num_envs, vec.n_agents
        obs_dim = vec.single_observation_space.shape[0]
        act_dim = vec.single_action_space.shape[0]
        vec.env.reset(seed=0)  # the template env (never stepped) tells the state size
        state_dim = int(vec.env.state().size)
        f32 = torch.float32
        self._safety = vec.safety is not None   # a filtered batch (satenv.vector: safety_filter)
        extra = ({"safety_intervened": Categorical(2, (b, m, 1), dtype=torch.bool, device=device),
                  "safety_delta": Unbounded((b, m, 1), dtype=f32, device=device)} if self._safety else {})
        extra["safety_cost"] = Unbounded((b, m, 1), dtype=f32, device=device)
        self.observation_spec = Composite(
            agents=Composite(observation=Unbounded((b, m, obs_dim), dtype=f32, device=device), **extra,
                             shape=(b, m), device=device),
            state=Unbounded((b, state_dim), dtype=f32, device=device), shape=(b,), device=device)
        self.action_spec = Composite(
            agents=Composite(action=Bounded(-1.0, 1.0, (b, m, act_dim), dtype=f32, device=device),
                             shape=(b, m), device=device), shape=(b,), device=device)
        self.reward_spec = Composite(
            agents=Composite(reward=Unbounded((b, m, 1), dtype=f32, device=device), shape=(b, m), device=device),
            shape=(b,), device=device)

        def flags(shape):
            return {k: Categorical(2, shape, dtype=torch.bool, device=device)
                    for k in ("done", "terminated", "truncated")}

        self.done_spec = Composite(**flags((b, 1)), agents=Composite(**flags((b, m, 1)), shape=(b, m), device=device),
                                   shape=(b,), device=device)

    def _observation(self, obs: np.ndarray) -> dict[str, Any]:
        return {"agents": {"observation": torch.as_tensor(obs, device=self.device)},
                "state": torch.as_tensor(self.vec.state(), dtype=torch.float32, device=self.device)}

    def _flags(self, term: np.ndarray, trunc: np.ndarray) -> dict[str, Any]:
        t = torch.as_tensor(term, device=self.device)[..., None]
        u = torch.as_tensor(trunc, device=self.device)[..., None]
        return {"done": (t | u)[:, 0], "terminated": t[:, 0], "truncated": u[:, 0],
                "agents": {"done": t | u, "terminated": t, "truncated": u}}

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        mask = None
        if tensordict is not None:
            for key in ("_reset", ("agents", "_reset")):
                r = tensordict.get(key, None)
                if r is not None:
                    r = r.reshape(self.vec.num_envs, -1).any(-1).cpu().numpy()
                    mask = r if mask is None else (mask | r)
        if mask is None or mask.all():
            obs, _ = self.vec.reset()
        else:
            obs, _ = self.vec.reset(indices=mask)
        zeros = np.zeros((self.vec.num_envs, self.vec.n_agents), dtype=bool)
        data = _merge(self._flags(zeros, zeros), "agents", self._observation(obs))
        data["state"] = self._observation(obs)["state"]
        self._safety_entries(data, {"safety_intervened": zeros, "safety_delta": zeros.astype(np.float32),
                                    "safety_cost": zeros.astype(np.float32)})
        return self._tensordict(data)

    def _safety_entries(self, data: dict[str, Any], infos: dict[str, Any]) -> None:
        keys = ((("safety_intervened", torch.bool), ("safety_delta", torch.float32)) if self._safety else ())
        for key, dtype in (*keys, ("safety_cost", torch.float32)):
            data["agents"][key] = torch.as_tensor(np.asarray(infos[key]), dtype=dtype, device=self.device)[..., None]

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get(("agents", "action")).detach().cpu().numpy()
        obs, rew, term, trunc, infos = self.vec.step(action)
        reward = torch.as_tensor(rew, dtype=torch.float32, device=self.device)[..., None]
        data = _merge(self._flags(term, trunc), "agents", self._observation(obs))
        data["agents"]["reward"] = reward
        data["state"] = self._observation(obs)["state"]
        self._safety_entries(data, infos)
        return self._tensordict(data)

    def _tensordict(self, data: dict[str, Any]) -> TensorDictBase:
        agents = TensorDict(data.pop("agents"), batch_size=(self.vec.num_envs, self.vec.n_agents), device=self.device)
        return TensorDict({**data, "agents": agents}, batch_size=self.batch_size, device=self.device)

    def _set_seed(self, seed: int | None) -> None:
        self.vec.seed(None if seed is None else int(seed))


def _merge(flags: dict[str, Any], group: str, obs: dict[str, Any]) -> dict[str, Any]:
    out = dict(flags)
    out[group] = {**flags[group], **obs[group]}
    return out
