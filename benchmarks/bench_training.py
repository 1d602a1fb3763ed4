"""Training throughput: SB3 PPO ``learn()`` on ``SatVecEnv`` vs SB3 ``DummyVecEnv`` over the same env.

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.bench_training --copies 64 --rollouts 3 --out bench.json

Both sides run ``B`` copies of the same scenario (default platoon_v0, randomised initial states)
and the same PPO settings (``n_steps`` per row, 4 minibatches per rollout, ``n_epochs``):

* ``satenv``: :class:`training.vec_env.SatVecEnv` — one batched core step for all copies,
  parameter sharing (``B * M`` rows of one agent's observation);
* ``dummy``: ``DummyVecEnv`` of ``B`` :class:`training.gym_view.CentralisedEnv` (one PettingZoo
  env per copy, stepped in a Python loop, one row per copy with the concatenated observation) —
  the route SB3 offers without a batched env.

Reported: scenario env-steps/s (one step of one copy) and agent-steps/s during ``learn()``, the
ratio satenv/dummy, and the raw stepping rate of each VecEnv with random actions (no learner).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from typing import Any

import numpy as np


def _ppo(venv, n_steps: int, n_epochs: int, seed: int):
    from stable_baselines3 import PPO

    rollout = n_steps * venv.num_envs
    return PPO("MlpPolicy", venv, n_steps=n_steps, batch_size=max(rollout // 4, 2), n_epochs=n_epochs,
               seed=seed, device="cpu", verbose=0, policy_kwargs={"net_arch": [64, 64]})


def _raw_rate(venv, steps: int) -> float:
    venv.reset()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, size=(steps, venv.num_envs, *venv.action_space.shape)).astype(np.float32)
    t0 = time.perf_counter()
    for k in range(steps):
        venv.step(actions[k])
    return steps / (time.perf_counter() - t0)  # vec steps per second


def bench(env_id: str, env_kwargs: dict[str, Any], copies: int, n_steps: int, rollouts: int,
          n_epochs: int, seed: int) -> dict[str, Any]:
    import torch
    from stable_baselines3.common.vec_env import DummyVecEnv

    from training.gym_view import CentralisedEnv
    from training.vec_env import SatVecEnv, make_env

    torch.set_num_threads(1)
    m = len(make_env(env_id, **env_kwargs).possible_agents)
    out: dict[str, Any] = {}
    makers = {
        "satenv": (lambda: SatVecEnv(make_env(env_id, **env_kwargs), copies, seed=seed), m),
        "dummy": (lambda: DummyVecEnv([lambda: CentralisedEnv(make_env(env_id, **env_kwargs))
                                       for _ in range(copies)]), 1),
    }
    for name, (make, agents_per_row_inv) in makers.items():
        venv = make()
        rows = venv.num_envs
        rate = _raw_rate(venv, 200)
        model = _ppo(venv, n_steps, n_epochs, seed)
        total = rollouts * n_steps * rows
        t0 = time.perf_counter()
        model.learn(total_timesteps=total)
        wall = time.perf_counter() - t0
        scenario_steps = model.num_timesteps // agents_per_row_inv  # satenv rows are agents
        out[name] = {
            "rows": rows,
            "learn_wall_s": round(wall, 3),
            "learn_scenario_steps": int(scenario_steps),
            "learn_env_steps_per_s": scenario_steps / wall,
            "learn_agent_steps_per_s": scenario_steps * m / wall,
            "raw_env_steps_per_s": rate * copies,
            "raw_agent_steps_per_s": rate * copies * m,
        }
        venv.close()
    out["ratio_learn_env_steps_per_s"] = out["satenv"]["learn_env_steps_per_s"] / out["dummy"]["learn_env_steps_per_s"]
    out["ratio_raw_env_steps_per_s"] = out["satenv"]["raw_env_steps_per_s"] / out["dummy"]["raw_env_steps_per_s"]
    return out


def main(argv: list[str] | None = None) -> dict[str, Any]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--env-id", default="platoon_v0")
    p.add_argument("--env-kwargs", default='{"randomize": true}', help="JSON object")
    p.add_argument("--copies", type=int, default=64)
    p.add_argument("--n-steps", type=int, default=128)
    p.add_argument("--rollouts", type=int, default=3)
    p.add_argument("--n-epochs", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="write the results as JSON")
    a = p.parse_args(argv)
    res = bench(a.env_id, json.loads(a.env_kwargs), a.copies, a.n_steps, a.rollouts, a.n_epochs, a.seed)
    res["settings"] = {**vars(a), "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
                       "python": platform.python_version(), "cpus": os.cpu_count()}
    for name in ("satenv", "dummy"):
        r = res[name]
        print(f"{name:7s} rows={r['rows']:5d}  learn: {r['learn_env_steps_per_s']:9.0f} env-steps/s "
              f"({r['learn_agent_steps_per_s']:9.0f} agent-steps/s)  raw stepping: "
              f"{r['raw_env_steps_per_s']:9.0f} env-steps/s")
    print(f"ratio satenv/dummy: learn {res['ratio_learn_env_steps_per_s']:.1f}x, "
          f"raw stepping {res['ratio_raw_env_steps_per_s']:.1f}x")
    if a.out:
        with open(a.out, "w") as fh:
            json.dump(res, fh, indent=2)
    return res


if __name__ == "__main__":
    main()
