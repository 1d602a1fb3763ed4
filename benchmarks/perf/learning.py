"""The ``learning`` section: the native TorchRL env against TorchRL's generic wrapper, and
end-to-end training agent-steps/s of SB3 PPO, BenchMARL MAPPO and RLlib PPO."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from ._common import AGENTS


def learning_throughput(batch: int = 256, frames: int = 20_000, steps: int = 100,
                        log: Callable[[str], None] = print) -> dict:
    """The ``learning`` section: TorchRL envs (env only) and end-to-end training, agent-steps/s."""
    out: dict[str, Any] = {"env_id": "platoon_v0", "agents": AGENTS, "net_arch": [64, 64]}
    try:
        import torch
        from torchrl.envs.libs.pettingzoo import PettingZooWrapper

        import satenv
        from satenv.torchrl import make_env

        torch.set_num_threads(1)

        def rollout_rate(env, n: int, copies: int) -> float:
            td = env.reset()
            t0 = time.perf_counter()
            env.rollout(n, break_when_any_done=False, tensordict=td, auto_reset=False)
            return n * copies * AGENTS / (time.perf_counter() - t0)

        native = rollout_rate(make_env("platoon_v0", batch, seed=0), steps, batch)
        wrapper = rollout_rate(PettingZooWrapper(satenv.make("platoon_v0"), use_mask=False,
                                                 categorical_actions=False, done_on_any=True), steps, 1)
        out["torchrl"] = {"batch": batch, "native_agent_steps_per_s": native,
                          "pettingzoo_wrapper_agent_steps_per_s": wrapper, "ratio": native / wrapper}
        log(f"(e) torchrl native batch {batch}: {native:.3g} agent-steps/s; PettingZooWrapper: "
            f"{wrapper:.3g} ({native / wrapper:.0f}x)")
    except ImportError as err:
        out["torchrl"] = {"skipped": f"torchrl not installed ({err})"}
    out["training"] = {name: _train_rate(name, frames) for name in ("sb3_ppo", "benchmarl_mappo", "rllib_ppo")}
    for name, row in out["training"].items():
        log(f"(f) {name}: " + (f"skipped ({row['skipped']})" if "skipped" in row
                               else f"{row['agent_steps_per_s']:.3g} agent-steps/s end to end"))
    return out


def _train_rate(name: str, frames: int) -> dict:
    """Agent-steps/s of one training stack on platoon_v0 (``frames`` env steps of one copy)."""
    import tempfile

    copies = 16
    with tempfile.TemporaryDirectory() as tmp:
        try:
            if name == "sb3_ppo":
                from stable_baselines3 import PPO

                import satenv
                from training.vec_env import SatVecEnv

                vec = SatVecEnv(satenv.make("platoon_v0"), copies, seed=0)
                model = PPO("MlpPolicy", vec, n_steps=64, batch_size=1024, n_epochs=5, device="cpu", seed=0,
                            policy_kwargs={"net_arch": [64, 64]})
                t0 = time.perf_counter()
                model.learn(total_timesteps=frames * AGENTS)
                return {"agent_steps": model.num_timesteps, "agent_steps_per_s": model.num_timesteps / (time.perf_counter() - t0)}
            if name == "benchmarl_mappo":
                from training.benchmarl_train import BenchMARLConfig, build_experiment

                exp = build_experiment(BenchMARLConfig(max_frames=frames, frames_per_batch=min(frames, 64 * copies),
                                                       num_envs=copies, minibatch_size=1024 // AGENTS,
                                                       minibatch_iters=5, out_dir=tmp))
                t0 = time.perf_counter()
                exp.run()
                return {"agent_steps": exp.total_frames * AGENTS,
                        "agent_steps_per_s": exp.total_frames * AGENTS / (time.perf_counter() - t0)}
            from training.rllib_train import RLlibConfig, run

            batch = min(frames, 64 * copies)
            rows = run(RLlibConfig(iterations=max(1, frames // batch), train_batch_size=batch,
                                   minibatch_size=min(batch, 1024 // AGENTS), num_epochs=5, out_dir=tmp), verbose=False)
            return {"agent_steps": rows[-1]["env_steps"] * AGENTS,
                    "agent_steps_per_s": rows[-1]["env_steps"] * AGENTS / rows[-1]["wall_s"]}
        except ImportError as err:
            return {"skipped": f"{name}: extra not installed ({err})"}
