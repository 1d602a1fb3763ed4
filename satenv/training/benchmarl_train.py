"""Train a satenv env with BenchMARL (MAPPO, IPPO, MASAC, ISAC, MADDPG, IDDPG) and export the actor.

    satenv train-marl --algo mappo --env-id platoon_v0 \\
        --env-kwargs '{"randomize": true}' --budget 12000000 --out-dir runs/platoon_mappo
    satenv board --policy runs/platoon_mappo/final      # rank it

Needs the ``marl`` extra (``pip install -c constraints.txt -e ".[marl]"``). The env is the native
TorchRL env (:mod:`satenv.torchrl`, batched numpy core) as the BenchMARL task
:class:`satenv.training.benchmarl_task.SatenvTask`. ``--budget`` counts agent-steps, as for every
trainer; BenchMARL counts frames, env steps of one copy (all agents at once), so the run
collects ``budget / agents`` frames (``--max-frames``, the old flag, gives frames directly). One
actor shared by every agent (``share_policy_params``).

``--out-dir`` holds ``config.json`` (the run's config, with the frame budget actually run),
``final/``: the exported policy (the safe format of :mod:`satenv.training.policy`: ``policy.json``,
``weights.pt``, ``obs_norm.json`` (identity: BenchMARL does not normalise), ``env.json``,
``config.json``, ``manifest.json``, ``eval.json`` on ``--test-seeds`` beside the baselines), so
``satenv.training.load(DIR/final)`` and ``satenv board --policy DIR/final`` take it; and ``benchmarl/``:
BenchMARL's experiment folder (CSV logs under ``scalars/``, checkpoints every
``--checkpoint-every`` frames and at the end; those are BenchMARL's own pickled files, for
resuming with BenchMARL, not for sharing).
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

from satenv.cliargs import Arg
from satenv.training.config import RunConfig, announce, check_int, check_number, parse_args

__all__ = ["BenchMARLConfig", "run", "main", "export_actor", "ALGORITHMS"]

ALGORITHMS = ("mappo", "ippo", "masac", "isac", "maddpg", "iddpg")
"""BenchMARL's continuous-action algorithms."""


@dataclass(frozen=True)
class BenchMARLConfig(RunConfig):
    """One BenchMARL run (``satenv train-marl``; frames are env steps of one copy)."""

    algorithm: Annotated[Literal["mappo", "ippo", "masac", "isac", "maddpg", "iddpg"],
                         Arg(name="algo")] = "mappo"
    """BenchMARL algorithm (continuous actions; ``algorithm`` in ``config.json``)."""
    budget: int | None = None
    """The budget: agent-steps to train for; the run collects ``ceil(budget / agents)`` frames,
    rounded up to whole batches (printed and saved). None: ``max_frames``."""
    max_frames: int = 1_000_000
    """The old budget flag, in frames (env steps of one copy: agent-steps / agents), used when
    ``--budget`` is not given; rounded up to whole batches (the rounded figure is printed and saved)."""
    frames_per_batch: int = 6000
    """Frames per collection batch (capped at ``max_frames``, rounded up to a multiple of ``num_envs``)."""
    num_envs: int = 10
    """Env copies per collector (one batched core)."""
    minibatch_size: int = 400
    """Minibatch size (on-policy) or train batch size (off-policy)."""
    minibatch_iters: int = 45
    """Minibatch iterations (on-policy) or optimiser steps (off-policy) per batch."""
    lr: float = 5e-5
    """Learning rate."""
    gamma: float = 0.99
    """Discount factor."""
    checkpoint_every: int = 0
    """BenchMARL checkpoint every this many frames (0: only at the end)."""
    out_dir: str = "runs/benchmarl"
    """Run folder: ``config.json``, ``benchmarl/`` (BenchMARL's own), ``final/`` (the policy with ``eval.json``)."""
    init_actor: str = ""
    """Start the actor from this policy folder (``satenv imitate --squash true``, same
    ``--net-arch``) instead of at random."""
    init_std: float = 0.2
    """The seeded actor's initial action standard deviation."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm must be one of {ALGORITHMS} (continuous actions), got {self.algorithm!r}")
        for name in ("max_frames", "frames_per_batch", "num_envs", "minibatch_size", "minibatch_iters"):
            check_int(name, getattr(self, name), minimum=1)
        if self.budget is not None:
            check_int("budget", self.budget, minimum=1)
        check_int("checkpoint_every", self.checkpoint_every, minimum=0)
        if not isinstance(self.init_actor, str):
            raise ValueError(f"init_actor must be a policy folder path or '', got {self.init_actor!r}")
        if not (isinstance(self.init_std, (int, float)) and 0 < self.init_std < 10):
            raise ValueError(f"init_std must be a number in (0, 10), got {self.init_std!r}")
        check_number("gamma", self.gamma, 0.0, 1.0)

    def planned(self, n_agents: int | None = None) -> BenchMARLConfig:
        """The config actually run: ``max_frames`` from ``budget`` (``ceil(budget / n_agents)``;
        ``n_agents`` needed then), ``frames_per_batch`` capped at ``max_frames`` and rounded up to
        whole env steps of ``num_envs`` copies, ``max_frames`` rounded up to whole batches."""
        frames = self.max_frames
        if self.budget is not None:
            if n_agents is None:
                raise ValueError("planned(n_agents): the budget is in agent-steps; give the env's agent count")
            frames = -(-self.budget // n_agents)
        per_batch = -(-min(self.frames_per_batch, frames) // self.num_envs) * self.num_envs
        return self.replace(frames_per_batch=per_batch, max_frames=-(-frames // per_batch) * per_batch)


def build_experiment(cfg: BenchMARLConfig):
    """The BenchMARL ``Experiment`` of ``cfg`` (CSV logger, CPU, its folder under ``out_dir/benchmarl``)."""
    import benchmarl.algorithms as algos
    import torch
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    from satenv.training.benchmarl_task import task_for

    task = task_for(cfg.env_id, cfg.env_kwargs)
    algo_cls = {"mappo": algos.MappoConfig, "ippo": algos.IppoConfig, "masac": algos.MasacConfig,
                "isac": algos.IsacConfig, "maddpg": algos.MaddpgConfig, "iddpg": algos.IddpgConfig}[cfg.algorithm]
    ec = ExperimentConfig.get_from_yaml()
    ec.max_n_frames = cfg.max_frames
    ec.on_policy_collected_frames_per_batch = ec.off_policy_collected_frames_per_batch = cfg.frames_per_batch
    ec.on_policy_n_envs_per_worker = ec.off_policy_n_envs_per_worker = cfg.num_envs
    ec.on_policy_minibatch_size = ec.off_policy_train_batch_size = cfg.minibatch_size
    ec.on_policy_n_minibatch_iters = ec.off_policy_n_optimizer_steps = cfg.minibatch_iters
    ec.lr, ec.gamma = cfg.lr, cfg.gamma
    ec.loggers = ["csv"]
    ec.evaluation = ec.render = False
    ec.checkpoint_interval = cfg.checkpoint_every
    ec.checkpoint_at_end = True
    folder = Path(cfg.out_dir) / "benchmarl"
    folder.mkdir(parents=True, exist_ok=True)
    ec.save_folder = str(folder)
    model = MlpConfig(num_cells=list(cfg.net_arch), activation_class=torch.nn.Tanh, layer_class=torch.nn.Linear)
    return Experiment(task=task, algorithm_config=algo_cls.get_from_yaml(),
                      model_config=model, critic_model_config=model, seed=cfg.seed, config=ec)


def export_actor(policy: Any, obs_dim: int, act_dim: int, n_agents: int):
    """The deterministic actor of a trained BenchMARL policy as a :class:`satenv.training.actor.MLPActor`.

    Reads the shared MLP's layers (the first ``act_dim`` outputs are the action location when
    the policy outputs ``loc, scale``) and whether the action is squashed by ``tanh``, then
    checks on random observations that it reproduces the policy's deterministic actions.
    """
    import torch
    from benchmarl.models.mlp import Mlp
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from satenv.training.actor import MLPActor

    mlps = [m for m in policy.modules() if isinstance(m, Mlp)]
    if len(mlps) != 1:
        raise ValueError(f"expected one shared BenchMARL Mlp in the policy, found {len(mlps)}")
    params = dict(mlps[0].mlp.params.flatten_keys(".").items())
    layers = sorted({int(k.split(".")[0]) for k in params})
    weights = [(params[f"{i}.weight"].detach(), params[f"{i}.bias"].detach()) for i in layers]
    if any(w.ndim != 2 for w, _ in weights):
        raise ValueError("the policy's MLP is not parameter-shared (use share_policy_params=True)")
    w, b = weights[-1]
    weights[-1] = (w[:act_dim], b[:act_dim])  # loc of (loc, scale), or the action itself
    obs = torch.randn(64, n_agents, obs_dim) * 3
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        expected = policy(TensorDict({("agents", "observation"): obs}, batch_size=[64]))["agents", "action"]
    hidden = [int(w.shape[0]) for w, _ in weights[:-1]]
    for squash in (True, False):
        actor = MLPActor(obs_dim, act_dim, hidden, "tanh", squash).copy_linear_weights(weights)
        with torch.no_grad():
            got = actor(obs)
        if torch.allclose(got.clamp(-1, 1), expected.clamp(-1, 1), atol=1e-5):
            return actor
    raise ValueError("the exported actor does not reproduce the BenchMARL policy's deterministic actions")


def seed_actor(policy: Any, folder: str, init_std: float, n_agents: int) -> None:
    """Start a BenchMARL policy from the shipped-format policy in ``folder`` (e.g. a DAgger run of
    ``satenv imitate --squash true``): its layers, with the observation normaliser
    folded into the first one (``W / s``, ``b - W m / s``; the normaliser's clip is dropped), as
    the action location, and a constant standard deviation ``init_std`` (the scale rows zeroed,
    their bias set through BenchMARL's ``biased_softplus_1.0`` mapping). Checked: the BenchMARL
    policy's deterministic actions then match the seed's on in-distribution observations."""
    import math

    import numpy as np
    import torch
    from benchmarl.models.mlp import Mlp
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from satenv.training.policy import load

    seed = load(folder, shielded=False)   # the network is the seed, never its filter
    spec, norm = seed.actor.spec, seed.normalizer
    if not spec["squash"] or spec["activation"] != "tanh" or seed.features is not None or seed.action_map is not None:
        raise ValueError(f"init_actor {folder!r}: needs a tanh MLP with squash=True and no feature/action maps, "
                         f"got {spec} (train it with satenv imitate --squash true)")
    mlps = [m for m in policy.modules() if isinstance(m, Mlp)]
    params = mlps[0].mlp.params.flatten_keys(".")
    indices = sorted({int(k.split(".")[0]) for k in params.keys()})
    layers = [(lin.weight.detach().double(), lin.bias.detach().double()) for lin in seed.actor.linear_layers()]
    if len(layers) != len(indices) or any(tuple(params[f"{i}.weight"].shape[-2:]) != tuple(w.shape)
                                          for i, (w, _) in zip(indices[:-1], layers[:-1], strict=True)):
        raise ValueError(f"init_actor {folder!r}: hidden layers {spec['hidden']} do not fit --net-arch")
    if norm.mean is not None:
        s = torch.as_tensor(np.sqrt(norm.var + norm.epsilon))
        w, b = layers[0]
        layers[0] = (w / s, b - (w / s) @ torch.as_tensor(norm.mean))
    w, b = layers[-1]
    scale_bias = math.log(math.expm1(init_std)) - math.log(math.expm1(1.0))  # biased_softplus_1.0
    layers[-1] = (torch.cat([w, torch.zeros_like(w)]), torch.cat([b, torch.full_like(b, scale_bias)]))
    with torch.no_grad():
        for i, (w, b) in zip(indices, layers, strict=True):
            params[f"{i}.weight"].data.copy_(w.float().expand_as(params[f"{i}.weight"]))
            params[f"{i}.bias"].data.copy_(b.float().expand_as(params[f"{i}.bias"]))
    raw = torch.as_tensor(np.random.default_rng(0).normal(
        norm.mean if norm.mean is not None else 0.0, np.sqrt(norm.var) if norm.var is not None else 1.0,
        (64, n_agents, spec["obs_dim"])), dtype=torch.float32)
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        got = policy(TensorDict({("agents", "observation"): raw}, batch_size=[64]))["agents", "action"]
    want = torch.as_tensor(seed.predict(raw.reshape(-1, spec["obs_dim"]).double().numpy())).reshape(got.shape)
    if not torch.allclose(got, want, atol=1e-3):
        raise ValueError(f"init_actor {folder!r}: the seeded BenchMARL policy does not reproduce the seed's "
                         f"actions (max difference {float((got - want).abs().max()):.3g})")


def _relative(path: Path, root: Path) -> str:
    """``path`` relative to the run folder ``root`` (the parent of ``final/``) where it lies inside it."""
    try:
        return str(path.resolve().relative_to(root.resolve()))
    except ValueError:
        return str(path)


def run(cfg: BenchMARLConfig) -> Path:
    """Train, export the actor to ``out_dir/final`` and evaluate it there; returns ``out_dir/final``."""
    import torch

    import satenv
    from satenv.training.envs import policy_env_meta
    from satenv.training.evaluate import run_summary
    from satenv.training.policy import LearnedPolicy, ObsNormalizer, save_artifacts

    torch.set_num_threads(cfg.torch_threads)
    out = Path(cfg.out_dir)
    env = satenv.make(cfg.env_id, **cfg.env_kwargs)
    planned = cfg.planned(len(env.possible_agents))
    if planned != cfg:
        given = f"budget {cfg.budget} agent-steps" if cfg.budget is not None else f"max_frames {cfg.max_frames}"
        print(f"{given} -> max_frames {planned.max_frames} ({planned.max_frames * len(env.possible_agents)} "
              f"agent-steps), frames_per_batch {cfg.frames_per_batch} -> {planned.frames_per_batch} (whole "
              "batches of whole env steps)", file=sys.stderr)
        cfg = planned
    announce(cfg, f"BenchMARL {cfg.algorithm.upper()}, {cfg.max_frames} frames "
             f"({cfg.max_frames * len(env.possible_agents)} agent-steps) in batches of {cfg.frames_per_batch}",
             tensorboard=False)
    experiment = build_experiment(cfg)
    (out / "config.json").write_text(json.dumps(cfg.to_json(), indent=2) + "\n")
    if cfg.init_actor:
        seed_actor(experiment.policy, cfg.init_actor, cfg.init_std, len(env.possible_agents))
    experiment.run()
    agent = env.possible_agents[0]
    obs_dim, act_dim = env.observation_space(agent).shape[0], env.action_space(agent).shape[0]
    actor = export_actor(experiment.policy, obs_dim, act_dim, len(env.possible_agents))
    meta = {**policy_env_meta(cfg.env_id, env, cfg.env_kwargs, cfg.resolved_eval_env_kwargs),
            "step": int(experiment.total_frames),
            "benchmarl_folder": _relative(Path(experiment.folder_name), out)}
    policy = LearnedPolicy(actor, ObsNormalizer(), obs_shape=(obs_dim,), meta=meta)
    summary = run_summary(cfg, policy, steps=int(experiment.total_frames))
    return save_artifacts(out / "final", policy, env_meta=meta, config=cfg.to_json(),
                          source=f"BenchMARL {cfg.algorithm.upper()}", evaluation=summary)


def main(argv: list[str] | None = None) -> Path:
    try:
        cfg, _ = parse_args(argv, cls=BenchMARLConfig, prog="satenv train-marl",
                            description=__doc__.split("\n\n")[0])
        import benchmarl  # noqa: F401
    except ImportError as err:
        raise SystemExit(f"error: satenv.training.benchmarl_train needs the marl extra ({err}): "
                         "pip install -c constraints.txt -e '.[marl]'") from None
    except ValueError as err:
        raise SystemExit(f"error: {err}") from None
    try:
        final = run(cfg)
    except ValueError as err:
        raise SystemExit(f"error: {err}") from None
    print(f"exported the trained actor to {final} (satenv.training.load / satenv board --policy)")
    return final


if __name__ == "__main__":
    main(sys.argv[1:])
