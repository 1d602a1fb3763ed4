"""The ``training`` section: SB3 PPO on the batched env against ``DummyVecEnv``."""

from __future__ import annotations

import time
from typing import Any

import numpy as np


def _ppo(venv, n_steps: int, n_epochs: int, seed: int):
    from stable_baselines3 import PPO

    rollout = n_steps * venv.num_envs
    return PPO("MlpPolicy", venv, n_steps=n_steps, batch_size=max(rollout // 4, 2), n_epochs=n_epochs,
               seed=seed, device="cpu", verbose=0, policy_kwargs={"net_arch": [64, 64]})


def _raw_rate(venv, steps: int) -> float:
    """Vector steps per second with uniform random actions."""
    venv.reset()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, size=(steps, venv.num_envs, *venv.action_space.shape)).astype(np.float32)
    t0 = time.perf_counter()
    for k in range(steps):
        venv.step(actions[k])
    return steps / (time.perf_counter() - t0)


def _learn_rates(venv, rows_per_copy: int, agents: int, copies: int, n_steps: int, rollouts: int,
                 n_epochs: int, seed: int) -> dict:
    rate = _raw_rate(venv, 200)
    model = _ppo(venv, n_steps, n_epochs, seed)
    t0 = time.perf_counter()
    model.learn(total_timesteps=rollouts * n_steps * venv.num_envs)
    wall = time.perf_counter() - t0
    env_steps = model.num_timesteps // rows_per_copy
    return {"rows": venv.num_envs, "learn_wall_s": round(wall, 3), "learn_scenario_steps": int(env_steps),
            "learn_env_steps_per_s": env_steps / wall, "learn_agent_steps_per_s": env_steps * agents / wall,
            "raw_env_steps_per_s": rate * copies, "raw_agent_steps_per_s": rate * copies * agents}


def training_throughput(env_id: str = "platoon_v0", env_kwargs: dict | None = None, copies: int = 64,
                        n_steps: int = 128, rollouts: int = 3, n_epochs: int = 10, seed: int = 0) -> dict:
    """SB3 PPO ``learn()`` env-steps/s on ``SatVecEnv`` (one batched core step for all copies,
    one row per agent) and on ``DummyVecEnv`` of ``CentralisedEnv`` (one PettingZoo env per copy,
    one row per copy), same PPO settings; and their raw stepping rates (random actions)."""
    import torch
    from stable_baselines3.common.vec_env import DummyVecEnv

    from satenv.training.gym_view import CentralisedEnv
    from satenv.training.vec_env import SatVecEnv, make_env

    env_kwargs = {"randomize": True} if env_kwargs is None else env_kwargs
    torch.set_num_threads(1)
    m = len(make_env(env_id, **env_kwargs).possible_agents)
    venvs = {"satenv": (lambda: SatVecEnv(make_env(env_id, **env_kwargs), copies, seed=seed), m),
             "dummy": (lambda: DummyVecEnv([lambda: CentralisedEnv(make_env(env_id, **env_kwargs))
                                            for _ in range(copies)]), 1)}
    out: dict[str, Any] = {"env_id": env_id, "env_kwargs": env_kwargs, "copies": copies}
    for name, (make, rows_per_copy) in venvs.items():
        venv = make()
        out[name] = _learn_rates(venv, rows_per_copy, m, copies, n_steps, rollouts, n_epochs, seed)
        venv.close()
    for kind in ("learn", "raw"):
        out[f"ratio_{kind}_env_steps_per_s"] = (out["satenv"][f"{kind}_env_steps_per_s"]
                                                / out["dummy"][f"{kind}_env_steps_per_s"])
    return out
