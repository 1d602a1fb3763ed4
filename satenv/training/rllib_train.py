"""Train a satenv scenario with Ray RLlib: multi-agent PPO, one policy shared by every agent.

    satenv train-rllib --env-id platoon_v0 --env-kwargs '{"randomize": true}' \\
        --budget 800000 --num-env-runners 2 --out-dir runs/rllib_platoon
    satenv board --policy runs/rllib_platoon/final      # rank it
    # on an existing Ray cluster (started with `ray start --head` on the head node and
    # `ray start --address=<head>:6379` on the workers):
    satenv train-rllib --address <head>:6379 --num-env-runners 32 ...

The env goes through RLlib's PettingZoo wrapper (``ParallelPettingZooEnv``); every agent maps to
the policy ``"shared"``. Without ``--address`` Ray starts locally (``num_cpus`` = ``--num-cpus``).
``--budget`` counts agent-steps, as for every trainer: ``ceil(budget / (train_batch_size *
agents))`` iterations (``--iterations``, the old flag, gives them directly).
RLlib runs are only reproducible with a fixed ``PYTHONHASHSEED`` (set it before starting
Python, e.g. ``PYTHONHASHSEED=0 satenv train-rllib ...``).

Needs the optional extra (``pip install -c constraints.txt -e ".[rllib]"``: ray[rllib], torch,
tensorboard; stable-baselines3 is not imported on this path). Without it, :func:`main` exits
with a clear message.

Output (``--out-dir``): ``checkpoint/`` (``Algorithm.save_to_path``; RLlib's own pickled files,
for resuming with RLlib), ``tb/`` (TensorBoard: episode return and length, env steps, learner
losses per iteration), ``progress.json`` (per iteration: env steps, mean episode return, wall
time), ``config.json`` (these arguments) and ``final/``: the trained actor exported to the safe
policy format of :mod:`satenv.training.policy` (``policy.json``, ``weights.pt``, ``obs_norm.json``
(identity), ``env.json``, ``manifest.json``, ``eval.json`` on ``--test-seeds`` beside the
baselines), so ``satenv.training.load(out_dir/final)`` and ``satenv board --policy
out_dir/final`` take it.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from satenv.training.config import RunConfig, announce, check_int, check_number, parse_args

__all__ = ["RLlibConfig", "run", "main", "require_ray"]


class RayNotInstalledError(ImportError):
    """``ray[rllib]`` is missing."""


def require_ray():
    """Import ray (and RLlib) or raise :class:`RayNotInstalledError` with the install command."""
    try:
        import ray
        import ray.rllib  # noqa: F401
    except ImportError as err:
        raise RayNotInstalledError(
            f"satenv.training.rllib_train needs Ray RLlib, which is not installed ({err}). Install the optional "
            "extra: pip install 'satenv[rllib]' (ray[rllib]; it pins gymnasium==1.2.2 — use the "
            "project's constraints.txt)") from None
    return ray


@dataclass(frozen=True)
class RLlibConfig(RunConfig):
    """One RLlib run (``satenv train-rllib``)."""

    budget: int | None = None
    """The budget: agent-steps to train for; runs ``ceil(budget / (train_batch_size * agents))``
    iterations (printed and saved). None: ``iterations``."""
    iterations: int = 20
    """The old budget flag: ``Algorithm.train()`` iterations (each about ``train_batch_size`` env
    steps of every agent), used when ``--budget`` is not given."""
    gamma: float = 0.99
    """Discount factor."""
    train_batch_size: int = 4000
    """Env steps per iteration (per learner)."""
    minibatch_size: int = 500
    """PPO minibatch size (<= ``train_batch_size``)."""
    num_epochs: int = 5
    """PPO epochs per iteration."""
    num_env_runners: int = 0
    """Remote env runners (0: sample in the driver)."""
    num_envs: int = 1
    """Env copies per env runner."""
    num_cpus: int = 2
    """CPUs of the local Ray instance (ignored with ``--address``)."""
    address: str | None = None
    """An existing Ray cluster, e.g. ``10.0.0.1:6379`` (default: start Ray locally)."""
    out_dir: str = "runs/rllib"
    """Run folder: ``config.json``, ``checkpoint/``, ``tb/``, ``progress.json``, ``final/``
    (the policy with ``eval.json``)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("iterations", "train_batch_size", "minibatch_size", "num_epochs", "num_envs", "num_cpus"):
            check_int(name, getattr(self, name), minimum=1)
        check_int("num_env_runners", self.num_env_runners, minimum=0)
        if self.budget is not None:
            check_int("budget", self.budget, minimum=1)
        check_number("gamma", self.gamma, 0.0, 1.0)
        if self.minibatch_size > self.train_batch_size:
            raise ValueError(f"minibatch_size ({self.minibatch_size}) must be <= train_batch_size "
                             f"({self.train_batch_size})")

    def planned(self, n_agents: int) -> RLlibConfig:
        """The config actually run: ``iterations`` from ``budget`` (agent-steps) when given."""
        if self.budget is None:
            return self
        return self.replace(iterations=-(-self.budget // (self.train_batch_size * n_agents)))


def _env_creator(env_id: str, env_kwargs: dict[str, Any]):
    def create(_config=None):
        from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

        from satenv.training.envs import make_env

        return ParallelPettingZooEnv(make_env(env_id, **env_kwargs))

    return create


def build_algo_config(cfg: RLlibConfig):
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.tune.registry import register_env

    name = f"satenv_{cfg.env_id.replace(':', '_').replace('.', '_')}"
    register_env(name, _env_creator(cfg.env_id, cfg.env_kwargs))
    return (
        PPOConfig()
        .environment(name)
        .framework("torch")
        .multi_agent(policies={"shared"}, policy_mapping_fn=lambda agent_id, *args, **kwargs: "shared")
        .env_runners(num_env_runners=cfg.num_env_runners, num_envs_per_env_runner=cfg.num_envs)
        .training(lr=cfg.lr, gamma=cfg.gamma, train_batch_size_per_learner=cfg.train_batch_size,
                  minibatch_size=cfg.minibatch_size, num_epochs=cfg.num_epochs)
        .rl_module(model_config=DefaultModelConfig(fcnet_hiddens=list(cfg.net_arch)))
        .debugging(seed=cfg.seed)
    )


def run(cfg: RLlibConfig, *, verbose: bool = True) -> list[dict[str, Any]]:
    """Train for ``cfg.iterations``; returns the per-iteration progress rows."""
    ray = require_ray()
    import torch

    torch.set_num_threads(cfg.torch_threads)
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    from satenv.training.envs import make_env

    planned = cfg.planned(len(make_env(cfg.env_id, **cfg.env_kwargs).possible_agents))
    if planned != cfg:
        print(f"budget {cfg.budget} agent-steps -> {planned.iterations} iterations of "
              f"{cfg.train_batch_size} env steps", file=sys.stderr)
        cfg = planned
    announce(cfg, f"RLlib PPO, {cfg.iterations} iterations of {cfg.train_batch_size} env steps")
    (out / "config.json").write_text(json.dumps(cfg.to_json(), indent=2) + "\n")
    started = False
    if not ray.is_initialized():
        if cfg.address:
            ray.init(address=cfg.address)
        else:
            ray.init(num_cpus=cfg.num_cpus, include_dashboard=False, log_to_driver=False)
        started = True
    progress: list[dict[str, Any]] = []
    from torch.utils.tensorboard import SummaryWriter

    writer = SummaryWriter(str(out / "tb"))
    try:
        algo = build_algo_config(cfg).build_algo()
        t0 = time.perf_counter()
        for it in range(1, cfg.iterations + 1):
            result = algo.train()
            runners = result.get("env_runners", {})
            row = {"iteration": it,
                   "env_steps": int(result.get("num_env_steps_sampled_lifetime",
                                               runners.get("num_env_steps_sampled_lifetime", 0)) or 0),
                   "episode_return_mean": _float(runners.get("episode_return_mean")),
                   "wall_s": round(time.perf_counter() - t0, 2)}
            progress.append(row)
            _log_tensorboard(writer, result, row["env_steps"])
            (out / "progress.json").write_text(json.dumps(progress, indent=1) + "\n")
            if verbose:
                print(f"iter {it}: {row}", flush=True)
        algo.save_to_path(str((out / "checkpoint").resolve()))
        export_policy(algo.get_module("shared"), cfg, steps=progress[-1]["env_steps"] if progress else 0)
        algo.stop()
    finally:
        writer.close()
        if started:
            ray.shutdown()
    return progress


def _log_tensorboard(writer, result: dict[str, Any], step: int) -> None:
    runners = result.get("env_runners", {})
    for key in ("episode_return_mean", "episode_len_mean", "num_episodes"):
        value = _float(runners.get(key))
        if value is not None:
            writer.add_scalar(f"env_runners/{key}", value, step)
    for key, value in (result.get("learners", {}).get("shared", {}) or {}).items():
        if _float(value) is not None and key.endswith(("loss", "entropy", "mean_kl_loss")):
            writer.add_scalar(f"learners/shared/{key}", _float(value), step)
    writer.flush()


def export_policy(module: Any, cfg: RLlibConfig, steps: int = 0) -> Path:
    """Write the RLModule's deterministic actor (the action mean) into ``cfg.out_dir/final`` in the
    safe policy format with its ``eval.json``; checks it reproduces the module on random observations."""
    import torch
    from torch import nn

    from satenv.training.actor import MLPActor
    from satenv.training.envs import make_env, policy_env_meta
    from satenv.training.policy import LearnedPolicy, ObsNormalizer, save_artifacts

    env = make_env(cfg.env_id, **cfg.env_kwargs)
    agent = env.possible_agents[0]
    obs_dim, act_dim = env.observation_space(agent).shape[0], env.action_space(agent).shape[0]
    encoder = getattr(module.encoder, "actor_encoder", None) or module.encoder.encoder
    layers = [m for m in encoder.modules() if isinstance(m, nn.Linear)] + \
             [m for m in module.pi.modules() if isinstance(m, nn.Linear)]
    acts = {type(m).__name__.lower() for m in encoder.modules()
            if type(m).__name__.lower() in ("tanh", "relu", "elu", "silu")}
    if len(acts) > 1:
        raise ValueError(f"cannot export an RLlib actor mixing activations {sorted(acts)}")
    w, b = layers[-1].weight.detach(), layers[-1].bias.detach()
    pairs = [(m.weight.detach(), m.bias.detach()) for m in layers[:-1]] + [(w[:act_dim], b[:act_dim])]
    actor = MLPActor(obs_dim, act_dim, [int(m.out_features) for m in layers[:-1]], acts.pop() if acts else "tanh")
    actor.copy_linear_weights(pairs)
    obs = torch.randn(64, obs_dim) * 3
    with torch.no_grad():
        expected = module.forward_inference({"obs": obs})["action_dist_inputs"][:, :act_dim]
        if not torch.allclose(actor(obs), expected, atol=1e-5):
            raise ValueError("the exported actor does not reproduce the RLlib module's action means")
    meta = {**policy_env_meta(cfg.env_id, env, cfg.env_kwargs, cfg.resolved_eval_env_kwargs), "step": int(steps)}
    policy = LearnedPolicy(actor, ObsNormalizer(), obs_shape=(obs_dim,), meta=meta)
    from satenv.training.evaluate import run_summary

    return save_artifacts(Path(cfg.out_dir) / "final", policy, env_meta=meta, config=cfg.to_json(),
                          source="RLlib PPO", evaluation=run_summary(cfg, policy, steps=int(steps)))


def _float(v: Any) -> float | None:
    try:
        return None if v is None else float(v)
    except (TypeError, ValueError):
        return None


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    try:
        cfg, _ = parse_args(argv, cls=RLlibConfig, prog="satenv train-rllib",
                            description=__doc__.split("\n\n")[0])
        return run(cfg)
    except (RayNotInstalledError, ValueError) as err:
        raise SystemExit(f"error: {err}") from None


if __name__ == "__main__":
    main(sys.argv[1:])
