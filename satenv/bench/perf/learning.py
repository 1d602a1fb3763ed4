"""The ``learning`` section: the native TorchRL env against TorchRL's generic wrapper, and
end-to-end training throughput of each trainer on each env with its fast configuration.

:data:`FAST_CONFIGS` is the documented fast configuration of each trainer (``docs/training.md``,
"Fast configurations"): the fields of ``satenv.training.config.TrainConfig`` (SB3 PPO,
``python -m satenv.training.train``), ``satenv.training.benchmarl_train.BenchMARLConfig`` (BenchMARL MAPPO) and
``satenv.training.imitation.ImitationConfig`` (DAgger) that set the speed. :func:`end_to_end` runs each
trainer's own building blocks with it for a few thousand agent-steps (no evaluation, no
checkpoints) and splits the wall time into

* ``env``: ``SatVectorEnv.step`` (SB3, BenchMARL: the batched core of every copy) or the
  PettingZoo ``env.step`` (DAgger);
* ``learner``: the gradient updates (SB3 ``model.train``, BenchMARL's optimiser loop, DAgger's
  regression ``fit``);
* ``expert`` (DAgger only): the scripted expert's ``act`` (the labels);
* the rest: policy inference during collection, buffers, adapters.

Each trainer runs once untimed first (torch's one-time costs: the first ``learn()`` of a process
ran 10x slower); DAgger gets :data:`DAGGER_LABEL_FRACTION` of the agent-steps.
"""

from __future__ import annotations

import contextlib
import tempfile
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from ._common import AGENTS

ENV_IDS = ("platoon_v0", "cluster_v0", "servicing_v0", "formation_v0")
TRAINERS = ("sb3_ppo", "benchmarl_mappo", "dagger")
DAGGER_TASKS = {"platoon_v0": "platoon-pereira2022", "cluster_v0": "cluster-li2022",
                "servicing_v0": "servicing-pereira2022", "formation_v0": "formation-kannan2022-position"}
"""The system whose training task and expert (:data:`satenv.tasks.SYSTEMS`) DAgger runs on each env
in the measurement."""
DAGGER_LABEL_FRACTION = {"platoon_v0": 1 / 16, "cluster_v0": 1 / 256, "servicing_v0": 1 / 256,
                         "formation_v0": 1 / 16}
"""DAgger's labels as a fraction of the section's agent-steps: the experts, not the learner, set its
pace (the servicing NMPC labels about 4 agent-steps/s at the episode start, the cluster's
re-planning tube-RDMPC a few per second)."""

FAST_CONFIGS: dict[str, dict[str, Any]] = {
    "sb3_ppo": {"num_envs": 64, "n_steps": 32, "batch_size": 4096, "n_epochs": 2, "net_arch": (64, 64),
                "torch_threads": 1},
    "benchmarl_mappo": {"num_envs": 64, "frames_per_batch": 64 * 32, "minibatch_size": 1024,
                        "minibatch_iters": 4, "net_arch": (64, 64), "torch_threads": 1},
    "dagger": {"episodes_per_round": 4, "epochs": 5, "batch_size": 2048, "net_arch": (64, 64),
               "torch_threads": 1},
}
"""The fast configuration of each trainer (config field -> value), the same on every env: large
batches (the learner, not the env, bounds training on these CPUs: one gradient step over 4096 rows
costs about what 64 small ones cost in Python overhead), few epochs per batch, a 64-64 MLP and one
torch thread (a second thread only competes with the env for the other core)."""


@contextlib.contextmanager
def _timed(owner: Any, name: str, acc: dict[str, float], key: str) -> Iterator[None]:
    """Accumulate the wall time of every call of ``owner.name`` into ``acc[key]`` while inside."""
    inner = getattr(owner, name)

    def timed(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return inner(*args, **kwargs)
        finally:
            acc[key] += time.perf_counter() - t0

    setattr(owner, name, timed)
    try:
        yield
    finally:
        if isinstance(owner, type):
            setattr(owner, name, inner)
        else:
            delattr(owner, name)


def _row(agent_steps: int, wall: float, acc: dict[str, float], config: dict[str, Any]) -> dict:
    return {"agent_steps": int(agent_steps), "wall_s": round(wall, 3), "agent_steps_per_s": agent_steps / wall,
            **{f"{k}_share": v / wall for k, v in acc.items()}, "config": config}


def _sb3(env_id: str, agent_steps: int, out_dir: str, fast: dict[str, Any]) -> dict:
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from satenv import tasks
    from satenv.training.config import TrainConfig
    from satenv.training.envs import make_env
    from satenv.training.train import build_model
    from satenv.training.vec_env import SatVecEnv
    from satenv.vector import SatVectorEnv

    where = {"task": env_id} if env_id in tasks.TASKS else {"env_id": env_id}   # an env id or a task name
    cfg = TrainConfig(**where, out_dir=out_dir, **fast)
    env = make_env(cfg.env_id, **cfg.env_kwargs)
    venv = VecNormalize(VecMonitor(SatVecEnv(env, cfg.num_envs, seed=cfg.seed)), gamma=cfg.gamma)
    model = build_model(cfg, venv)
    rows = cfg.num_envs * len(env.possible_agents) * cfg.n_steps
    acc = {"env": 0.0, "learner": 0.0}
    with _timed(SatVectorEnv, "step", acc, "env"), _timed(model, "train", acc, "learner"):
        t0 = time.perf_counter()
        model.learn(total_timesteps=max(rows, -(-agent_steps // rows) * rows))
        wall = time.perf_counter() - t0
    venv.close()
    return _row(model.num_timesteps, wall, acc, fast)


def _benchmarl(env_id: str, agent_steps: int, out_dir: str, fast: dict[str, Any]) -> dict:
    import torch

    from satenv.training.benchmarl_train import BenchMARLConfig, build_experiment
    from satenv.vector import SatVectorEnv

    m = len(_agents(env_id))
    batch = BenchMARLConfig(**fast).frames_per_batch
    frames = max(batch, -(-agent_steps // (m * batch)) * batch)
    cfg = BenchMARLConfig(env_id=env_id, out_dir=out_dir, max_frames=frames, **fast).planned()
    torch.set_num_threads(cfg.torch_threads)
    exp = build_experiment(cfg)
    acc = {"env": 0.0, "learner": 0.0}
    with _timed(SatVectorEnv, "step", acc, "env"), _timed(exp, "_optimizer_loop", acc, "learner"):
        t0 = time.perf_counter()
        exp.run()
        wall = time.perf_counter() - t0
    return _row(exp.total_frames * m, wall, acc, fast)


def _dagger(env_id: str, agent_steps: int, out_dir: str, fast: dict[str, Any]) -> dict:
    """Two DAgger rounds (the expert's own flights, then the learner's with ``beta = 0.5``) of
    ``satenv.training.imitation``'s ``collect_episode`` and ``regress`` on episodes cut to ``max_steps`` so the
    rounds hold about ``agent_steps`` labels; evaluation and saving left out."""
    import torch

    from satenv import tasks
    from satenv.baselines.experts import make as make_expert
    from satenv.training.actor import MLPActor
    from satenv.training.envs import make_env
    from satenv.training.imitation import ImitationConfig as DaggerConfig
    from satenv.training.imitation import collect_episode
    from satenv.training.imitation.fit import regress
    from satenv.training.policy import LearnedPolicy, ObsNormalizer
    from satenv.training.shaping import ObsFeatures

    m = len(_agents(env_id))
    max_steps = max(2, agent_steps // (2 * DaggerConfig(**fast).episodes_per_round * m))
    system = tasks.system(DAGGER_TASKS[env_id])
    task = tasks.get(system.training_task)
    cfg = DaggerConfig(env_id=env_id, env_kwargs={**task.env_kwargs, "max_steps": max_steps}, out_dir=out_dir,
                       expert=system.expert, **fast)
    torch.set_num_threads(cfg.torch_threads)
    env = make_env(env_id, **cfg.env_kwargs)
    expert = make_expert(cfg.expert, env)
    agent = env.possible_agents[0]
    obs_dim, act_dim = env.observation_space(agent).shape[0], env.action_space(agent).shape[0]
    feats = ObsFeatures(cfg.obs_symlog_scale, cfg.obs_symlog_dims, cfg.obs_drop_dims)
    actor = MLPActor(feats.out_dim(obs_dim), act_dim, list(cfg.net_arch), cfg.activation, cfg.squash)
    generator, rng = torch.Generator().manual_seed(cfg.seed), np.random.default_rng(cfg.seed)
    acc = {"env": 0.0, "expert": 0.0, "learner": 0.0}
    xs, ys, normalizer = [], [], None
    with _timed(env, "step", acc, "env"), _timed(expert, "act", acc, "expert"):
        t0 = time.perf_counter()
        for k in range(2):
            learner = None if k == 0 else LearnedPolicy(actor, normalizer, obs_shape=(obs_dim,), features=feats)
            for e in range(cfg.episodes_per_round):
                rows, _ = collect_episode(env, expert, learner, cfg.train_seed + k * cfg.episodes_per_round + e,
                                          beta=cfg.beta ** k, rng=rng)
                xs.append(rows["obs"])
                ys.append(np.clip(rows["act"], -1, 1))
            x_all, y_all = np.concatenate(xs), np.concatenate(ys)
            if normalizer is None:
                fx = feats(x_all.astype(np.float64))
                normalizer = ObsNormalizer(fx.mean(0), fx.var(0), cfg.clip_obs)
            t1 = time.perf_counter()
            regress(actor, normalizer(feats(x_all.astype(np.float64))), y_all, lr=cfg.lr, epochs=cfg.epochs,
                    batch_size=cfg.batch_size, generator=generator, weight_decay=cfg.weight_decay)
            acc["learner"] += time.perf_counter() - t1
        wall = time.perf_counter() - t0
    return {**_row(sum(len(x) for x in xs), wall, acc, fast), "expert": cfg.expert,
            "episode_max_steps": max_steps}


def _agents(env_id: str) -> list[str]:
    import satenv

    return list(satenv.make(env_id).possible_agents)


TRAINER_RUNS: dict[str, Callable[[str, int, str, dict[str, Any]], dict]] = {
    "sb3_ppo": _sb3, "benchmarl_mappo": _benchmarl, "dagger": _dagger}


def end_to_end(trainer: str, env_id: str, agent_steps: int = 4096, config: dict[str, Any] | None = None) -> dict:
    """About ``agent_steps`` agent-steps of ``trainer`` (a key of :data:`FAST_CONFIGS`) on
    ``env_id`` with ``config`` (fields of the trainer's config; default: its fast configuration,
    ``{}``: the trainer's defaults): agent-steps/s and the env / learner (/ expert) shares of the
    wall time; ``{"skipped": why}`` when the trainer's extra is missing."""
    with tempfile.TemporaryDirectory() as tmp:
        try:
            return TRAINER_RUNS[trainer](env_id, agent_steps, tmp, FAST_CONFIGS[trainer] if config is None else config)
        except ImportError as err:
            return {"skipped": f"{trainer}: extra not installed ({err})"}


def _log_row(log: Callable[[str], None], name: str, row: dict) -> None:
    shares = ", ".join(f"{k[:-6]} {100 * v:.0f} %" for k, v in row.items() if k.endswith("_share"))
    log(f"(f) {name}: " + (f"skipped ({row['skipped']})" if "skipped" in row else
                           f"{row['agent_steps_per_s']:.3g} agent-steps/s ({shares})"))


def learning_throughput(batch: int = 256, agent_steps: int = 16384, steps: int = 100,
                        env_ids: tuple[str, ...] = ENV_IDS, trainers: tuple[str, ...] = TRAINERS,
                        log: Callable[[str], None] = print) -> dict:
    """The ``learning`` section: TorchRL envs (env only) and end-to-end training, agent-steps/s."""
    out: dict[str, Any] = {"torchrl_env_id": "platoon_v0", "agents": AGENTS, "fast_configs": FAST_CONFIGS}
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
    out["training"] = {}
    for trainer in trainers:
        end_to_end(trainer, env_ids[0], 64)       # warm-up: the first learn() pays torch's one-time costs
        rows = out["training"].setdefault(trainer, {})
        for env_id in env_ids:
            budget = max(16, int(agent_steps * DAGGER_LABEL_FRACTION[env_id]) if trainer == "dagger" else agent_steps)
            rows[env_id] = end_to_end(trainer, env_id, budget)
            _log_row(log, f"{trainer} {env_id}", rows[env_id])
        if "skipped" not in rows[env_ids[0]]:   # the trainer's default config, same env, same run
            ref = rows[f"{env_ids[0]} (defaults)"] = end_to_end(trainer, env_ids[0],
                                                                rows[env_ids[0]]["agent_steps"], {})
            ref["fast_speedup"] = rows[env_ids[0]]["agent_steps_per_s"] / ref["agent_steps_per_s"]
            _log_row(log, f"{trainer} {env_ids[0]} with its defaults", ref)
    return out
