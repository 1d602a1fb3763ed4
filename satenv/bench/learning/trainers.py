"""How each algorithm of the grid is trained, with an evaluation at every checkpoint.

Every trainer gets a :class:`~satenv.bench.learning.grid.Run` and a callback
``checkpoint(k, agent_steps, wall_s, make_policy)`` that it calls at each of the run's
checkpoints (``make_policy(env)`` gives that checkpoint's policy for an env, still valid after later
checkpoints, for the selection at the end; ``wall_s`` is the training wall time so far, evaluations
excluded). Each uses the project's own trainer at its documented
defaults (the lean learner's own on every task: one configuration per row, whatever tuned
configurations are committed), every run on its rung (``run.task``):

* ``ppo``, ``ippo``, ``mappo``, ``ppo_lag``: the lean learner (``satenv.training.rl.ppo.train``,
  the grid's default trainer; ``ppo_lag`` is its PPO-Lagrangian option on the ``safety_cost`` info
  at the task's ``cost_budget``) run to each checkpoint's budget in turn, resuming bit for bit from
  its own checkpoint; the filter-in-training row trains on ``task.make_env(safety_filter=True)``
  (the filter's defaults: every action filtered, no reward penalty for a correction);
* ``masac``: ``satenv.training.benchmarl_train.build_experiment`` (the fast configuration, with
  :data:`~satenv.bench.learning.grid.MASAC_UTD` gradient steps per frame, each of
  :data:`~satenv.bench.learning.grid.MASAC_BATCH` frames) with a BenchMARL callback
  that exports the actor (``satenv.training.benchmarl_train.export_actor``) at each checkpoint;
* ``dagger``: ``satenv.training.imitation.run`` (the project's one imitation engine, the system's expert
  and hyper-parameters from :data:`satenv.tasks.SYSTEMS`) one round per checkpoint.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from satenv.bench.learning.grid import CHECKPOINTS, FILTER_PENALTY, MASAC_BATCH, MASAC_UTD, Run

__all__ = ["Checkpoint", "DAGGER_EPISODES", "filtered_task_env", "train"]

Checkpoint = Callable[[int, int, float, Callable[[Any], Any]], None]

DAGGER_EPISODES: dict[str, int] = {
    "platoon-pereira2023": 4, "platoon-pereira2022": 4, "formation-kannan2022-position": 1,
    "formation-kannan2022-collision": 1, "cluster-li2022": 1, "servicing-pereira2022": 1}
"""DAgger's episodes per round (round 0: the expert flies; each later round the network flies and
the expert labels): one round per checkpoint, so the labels are ``CHECKPOINTS x this x agents x
episode steps`` (:data:`satenv.bench.learning.grid.DAGGER_LABELS`)."""


def filtered_task_env(task: str, penalty: float = FILTER_PENALTY, safety: dict[str, Any] | None = None,
                      **overrides: Any) -> Any:
    """The training task's env with the safety filter inside its ``step`` and the intervention
    penalty on (an env id ``satenv.bench.learning.trainers:filtered_task_env`` for ``satenv.training.train``);
    ``safety``: the filter's other options (``satenv.safety.SafetyConfig`` fields, e.g. the margin a
    policy folder ships with, ``{"margin": 0.005}``)."""
    from satenv import tasks
    from satenv.safety import SafetyConfig

    config = SafetyConfig.from_options(SafetyConfig(penalty=penalty), **(safety or {}))
    return tasks.get(task).make_env(safety_filter=config, **overrides)


def _fast(trainer: str) -> dict[str, Any]:
    from satenv.bench.perf.learning import FAST_CONFIGS

    return dict(FAST_CONFIGS[trainer])


def lean_policy(final: Path, env: Any) -> Any:
    """The policy of a lean run's ``final/`` folder for ``env`` (IPPO: one folder per agent)."""
    from satenv import training
    from satenv.training.rl.ppo import PerAgentPolicy

    agents = final / "agents"
    if agents.is_dir():
        return PerAgentPolicy({a: training.load(agents / a, env=env) for a in env.possible_agents})
    return training.load(final, env=env)


def train_lean(run: Run, checkpoint: Checkpoint, workdir: Path) -> None:
    from satenv.training.rl import ppo

    task = run.task
    env = {"task": task.name, "env_kwargs": {"safety_filter": True} if run.filter else {}}
    variant = "ppo" if run.algorithm == "ppo_lag" else run.algorithm
    wall = 0.0
    for k, target in enumerate(run.checkpoints):
        cfg = ppo.LeanConfig(**env, variant=variant, lagrangian=run.algorithm == "ppo_lag",
                             seed=run.seed, budget=target, checkpoint_every=0, eval_baselines=(),
                             test_seeds=task.seeds("validation", 1), out_dir=str(workdir), progress=False)
        t0 = time.perf_counter()
        final = ppo.train(cfg, resume=k > 0)
        wall += time.perf_counter() - t0
        steps = json.loads((workdir / "progress.jsonl").read_text().splitlines()[-1])["agent_steps"]
        kept = shutil.copytree(final, workdir / "kept" / f"{k:04d}")   # the next segment rewrites final/
        checkpoint(k, steps, wall, lambda env, kept=kept: lean_policy(kept, env))


def benchmarl_config(run: Run, n_agents: int, workdir: Path) -> Any:
    """The BenchMARL config of a grid run: the fast configuration; off-policy rows take
    :data:`MASAC_UTD` gradient steps per collected frame, each of :data:`MASAC_BATCH` frames."""
    from satenv.training.benchmarl_train import BenchMARLConfig

    fast = _fast("benchmarl_mappo")
    if run.algorithm in ("masac", "isac"):
        fast["minibatch_iters"] = math.ceil(MASAC_UTD * fast["frames_per_batch"])
        fast["minibatch_size"] = MASAC_BATCH
    return BenchMARLConfig(algorithm=run.algorithm, task=run.task.name, seed=run.seed,
                           max_frames=math.ceil(run.budget / n_agents), out_dir=str(workdir), progress=False,
                           workers=1, **fast).planned()


def train_benchmarl(run: Run, checkpoint: Checkpoint, workdir: Path) -> None:
    from benchmarl.experiment.callback import Callback

    import satenv
    from satenv.training.benchmarl_train import build_experiment, export_actor
    from satenv.training.envs import policy_env_meta
    from satenv.training.policy import LearnedPolicy, ObsNormalizer

    task = run.task
    env = satenv.make(task.env_id, **task.env_kwargs)
    n_agents = len(env.possible_agents)
    agent = env.possible_agents[0]
    obs_dim, act_dim = env.observation_space(agent).shape[0], env.action_space(agent).shape[0]
    cfg = benchmarl_config(run, n_agents, workdir)
    experiment = build_experiment(cfg)
    experiment.config.checkpoint_at_end = False
    meta = policy_env_meta(task.env_id, env, dict(task.env_kwargs), dict(task.env_kwargs))
    targets = run.checkpoints

    class Checkpoints(Callback):
        def __init__(self) -> None:
            super().__init__()
            self.k, self.t0, self.eval_s = 0, time.perf_counter(), 0.0

        def on_train_end(self, training_td: Any, group: str) -> None:
            steps = int(self.experiment.total_frames) * n_agents
            while self.k < len(targets) and (steps >= targets[self.k] or steps >= cfg.max_frames * n_agents):
                t1 = time.perf_counter()
                actor = export_actor(self.experiment.policy, obs_dim, act_dim, n_agents)
                policy = LearnedPolicy(actor, ObsNormalizer(), obs_shape=(obs_dim,), meta={**meta, "step": steps})
                checkpoint(self.k, steps, t1 - self.t0 - self.eval_s, lambda _env, p=policy: p)
                self.eval_s += time.perf_counter() - t1
                self.k += 1

    cb = Checkpoints()
    cb.experiment = experiment
    experiment.callbacks.append(cb)
    experiment.run()
    if cb.k < len(targets):
        raise RuntimeError(f"{run.label()}: BenchMARL stopped at {experiment.total_frames} frames, before "
                           f"checkpoint {cb.k + 1} of {len(targets)}")


def train_dagger(run: Run, checkpoint: Checkpoint, workdir: Path) -> None:
    import dataclasses

    from satenv import training
    from satenv.training import imitation

    task = run.task
    fast = {k: v for k, v in _fast("dagger").items() if k != "torch_threads"}
    episodes = DAGGER_EPISODES[run.system]
    cfg = imitation.system_config(run.system, **{**fast, "task": task.name, "seed": run.seed,
                                              "train_seed": task.seeds("train")[0] + 10_000 * run.seed,
                                              "round0_episodes": episodes, "episodes_per_round": episodes,
                                              "eval_seeds": task.seeds("validation", 1), "final_eval": False})
    for k in range(CHECKPOINTS):
        imitation.run(dataclasses.replace(cfg, rounds=k + 1), workdir)
        history = json.loads((workdir / "history.json").read_text())
        wall = sum(h["collect_s"] + h["fit_s"] for h in history)
        folder = workdir / "rounds" / f"{k:04d}"
        checkpoint(k, int(history[-1]["labels"]), wall, lambda env, folder=folder: training.load(folder, env=env))


TRAINERS: dict[str, Callable[[Run, Checkpoint, Path], None]] = {
    "ppo": train_lean, "ippo": train_lean, "mappo": train_lean, "ppo_lag": train_lean, "masac": train_benchmarl,
    "dagger": train_dagger}


def train(run: Run, checkpoint: Checkpoint, finish: Callable[[], None] = lambda: None) -> None:
    """Train ``run`` in a temporary folder (weights are not kept), calling ``checkpoint`` at each
    checkpoint and ``finish`` after the last, while every checkpoint's policy can still be made; the
    controller (no training) is one checkpoint of its scripted policy."""
    if run.algorithm == "controller":
        from satenv import baselines
        checkpoint(0, 0, 0.0, lambda env: baselines.make(run.task.controller, env))
        finish()
        return
    with tempfile.TemporaryDirectory(prefix=f"learning-{run.algorithm}-") as d:
        TRAINERS[run.algorithm](run, checkpoint, Path(d))
        finish()
