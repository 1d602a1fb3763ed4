"""Run one episode of a policy in an environment and record it as arrays."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class Trajectory:
    """One recorded episode (``T`` steps, ``M`` agents), everything as arrays.

    ``info[key]`` has shape ``(T + 1, M, ...)``: entry 0 comes from ``reset()``, entry ``k`` from
    the ``k``-th ``step()`` (so ``info["accel"][k]`` is the acceleration applied from ``k-1`` to
    ``k`` and ``info["accel"][0]`` is zero). ``success_tol`` [m] and ``collision_voids_success``
    are the scenario's success rule (:func:`satenv.metrics.success`).
    """

    env_id: str
    agents: list[str]
    dt: float
    t: np.ndarray                    # (T+1,) [s]
    states: np.ndarray               # (T+1, M, d) true states
    actions: np.ndarray              # (T, M, action_dim) normalised actions as given
    rewards: np.ndarray              # (T, M)
    info: dict[str, np.ndarray]      # key -> (T+1, M, ...)
    terminated: bool = False
    truncated: bool = False
    compute_time: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (T,) s per act()
    policy_info: dict[str, Any] = field(default_factory=dict)
    seed: int | None = None
    success_tol: float = 1.0
    collision_voids_success: bool = True

    @property
    def steps(self) -> int:
        return int(self.actions.shape[0])

    def save(self, path) -> None:
        """Save to a compressed ``.npz`` (scalars and lists in a JSON header)."""
        import json

        header = {"env_id": self.env_id, "agents": self.agents, "dt": self.dt,
                  "terminated": self.terminated, "truncated": self.truncated, "seed": self.seed,
                  "success_tol": self.success_tol, "collision_voids_success": self.collision_voids_success,
                  "policy_info": {k: v for k, v in self.policy_info.items()
                                  if isinstance(v, (int, float, str, bool, type(None)))}}
        arrays = {"t": self.t, "states": self.states, "actions": self.actions,
                  "rewards": self.rewards, "compute_time": self.compute_time}
        arrays.update({f"info__{k}": v for k, v in self.info.items()})
        np.savez_compressed(path, header=np.array(json.dumps(header)), **arrays)

    @classmethod
    def load(cls, path) -> Trajectory:
        import json

        with np.load(path) as data:
            header = json.loads(str(data["header"]))
            info = {k[len("info__"):]: data[k] for k in data.files if k.startswith("info__")}
            return cls(t=data["t"], states=data["states"], actions=data["actions"],
                       rewards=data["rewards"], compute_time=data["compute_time"], info=info, **header)


def _stack_infos(infos: list[dict[str, dict[str, Any]]], agents: list[str]) -> dict[str, np.ndarray]:
    keys = [k for k, v in infos[0][agents[0]].items() if np.asarray(v).dtype.kind in "biuf"]
    return {k: np.array([[np.asarray(step[a][k]) for a in agents] for step in infos]) for k in keys}


def rollout(env, policy, *, seed: int | None = None, options: dict | None = None,
            max_steps: int | None = None) -> Trajectory:
    """Run ``policy`` in the PettingZoo parallel ``env`` for one episode.

    The policy's ``reset(seed)`` is called after ``env.reset(seed)``; the wall time of every
    ``act()`` is recorded. The policy's ``info`` dict (fallback counts, solve times) is copied
    into the trajectory at the end, with the scenario's ``success_tol`` and
    ``collision_voids_success`` (the Trajectory's defaults for a scenario without them).
    """
    obs, info = env.reset(seed=seed, options=options)
    agents = list(env.possible_agents)
    policy.reset(seed=seed)
    infos, actions, rewards, times = [info], [], [], []
    terminated = truncated = False
    limit = max_steps if max_steps is not None else int(env.scenario.max_steps)
    for _ in range(limit):
        start = time.perf_counter()
        act = policy.act(obs)
        times.append(time.perf_counter() - start)
        obs, rew, term, trunc, info = env.step(act)
        actions.append([np.asarray(act[a], dtype=float) for a in agents])
        rewards.append([rew[a] for a in agents])
        infos.append(info)
        terminated, truncated = any(term.values()), any(trunc.values())
        if not env.agents:
            break
    stacked = _stack_infos(infos, agents)
    states = stacked.pop("state")
    sc = env.scenario
    dt = float(sc.dt)
    rule = {k: getattr(sc, k) for k in ("success_tol", "collision_voids_success") if hasattr(sc, k)}
    return Trajectory(
        env_id=env.metadata.get("name", type(env).__name__), agents=agents, dt=dt,
        t=np.arange(len(infos)) * dt, states=states,
        actions=np.array(actions).reshape(-1, len(agents), env.action_space(agents[0]).shape[0]),
        rewards=np.array(rewards).reshape(-1, len(agents)),
        info=stacked, terminated=terminated, truncated=truncated, compute_time=np.array(times),
        policy_info=dict(getattr(policy, "info", {}) or {}), seed=seed, **rule,
    )
