"""Train a satenv env with BenchMARL (MAPPO, IPPO, MASAC, ISAC, MADDPG, IDDPG) and export the actor.

    python -m training.benchmarl_train --algorithm mappo --env-id platoon_v0 \\
        --env-kwargs '{"randomize": true}' --max-frames 3000000 --out-dir runs/platoon_mappo
    python -m benchmarks.scoreboard --policy runs/platoon_mappo      # rank it

Needs the ``marl`` extra (``pip install -c constraints.txt -e ".[marl]"``). The env is the native
TorchRL env (:mod:`satenv.torchrl`, batched numpy core) as the BenchMARL task
:class:`training.benchmarl_task.SatenvTask`; frames count env steps of one copy (all agents at
once), BenchMARL's convention. One actor shared by every agent (``share_policy_params``).

``--out-dir`` holds the exported policy (the safe format of :mod:`training.policy`:
``policy.json``, ``weights.pt``, ``obs_norm.json`` (identity: BenchMARL does not normalise),
``env.json``, ``config.json``, ``manifest.json``, ``eval.json`` on ``--eval-seeds``), so
``training.load(DIR)`` and ``benchmarks.scoreboard --policy DIR`` take it; and ``benchmarl/``:
BenchMARL's experiment folder (CSV logs under ``scalars/``, checkpoints every
``--checkpoint-every`` frames and at the end; those are BenchMARL's own pickled files, for
resuming with BenchMARL, not for sharing).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from training.config import check_int, check_net_arch

__all__ = ["BenchMARLConfig", "run", "main", "export_actor", "ALGORITHMS"]

ALGORITHMS = ("mappo", "ippo", "masac", "isac", "maddpg", "iddpg")
"""BenchMARL's continuous-action algorithms."""


@dataclass(frozen=True)
class BenchMARLConfig:
    """One BenchMARL run (every field is a ``--flag``; frames are env steps of one copy)."""

    algorithm: str = "mappo"
    env_id: str = "platoon_v0"
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    max_frames: int = 1_000_000
    frames_per_batch: int = 6000
    num_envs: int = 10
    minibatch_size: int = 400
    minibatch_iters: int = 45
    net_arch: tuple[int, ...] = (64, 64)
    lr: float = 5e-5
    gamma: float = 0.99
    seed: int = 0
    checkpoint_every: int = 0
    eval_seeds: tuple[int, ...] = (10000, 10001, 10002)
    out_dir: str = "runs/benchmarl"
    init_actor: str = ""
    init_std: float = 0.2

    def __post_init__(self) -> None:
        if self.algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm must be one of {ALGORITHMS} (continuous actions), got {self.algorithm!r}")
        if not isinstance(self.env_kwargs, dict):
            raise ValueError(f"env_kwargs must be a dict (JSON object), got {self.env_kwargs!r}")
        for name in ("max_frames", "frames_per_batch", "num_envs", "minibatch_size", "minibatch_iters"):
            check_int(name, getattr(self, name), minimum=1)
        for name in ("seed", "checkpoint_every"):
            check_int(name, getattr(self, name), minimum=0)
        object.__setattr__(self, "net_arch", check_net_arch(self.net_arch))
        object.__setattr__(self, "eval_seeds", tuple(int(s) for s in self.eval_seeds))
        if not isinstance(self.init_actor, str):
            raise ValueError(f"init_actor must be a policy folder path or '', got {self.init_actor!r}")
        if not (isinstance(self.init_std, (int, float)) and 0 < self.init_std < 10):
            raise ValueError(f"init_std must be a number in (0, 10), got {self.init_std!r}")
        if not (self.lr > 0 and 0 < self.gamma <= 1):
            raise ValueError(f"lr must be > 0 and gamma in (0, 1], got lr={self.lr!r}, gamma={self.gamma!r}")


def build_experiment(cfg: BenchMARLConfig):
    """The BenchMARL ``Experiment`` of ``cfg`` (CSV logger, CPU, its folder under ``out_dir/benchmarl``)."""
    import benchmarl.algorithms as algos
    import torch
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    from training.benchmarl_task import task_for

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
    """The deterministic actor of a trained BenchMARL policy as a :class:`training.actor.MLPActor`.

    Reads the shared MLP's layers (the first ``act_dim`` outputs are the action location when
    the policy outputs ``loc, scale``) and whether the action is squashed by ``tanh``, then
    checks on random observations that it reproduces the policy's deterministic actions.
    """
    import torch
    from benchmarl.models.mlp import Mlp
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from training.actor import MLPActor

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
    :mod:`training.imitate` with ``squash=True``): its layers, with the observation normaliser
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

    from training.policy import load

    seed = load(folder)
    spec, norm = seed.actor.spec, seed.normalizer
    if not spec["squash"] or spec["activation"] != "tanh" or seed.features is not None or seed.action_map is not None:
        raise ValueError(f"init_actor {folder!r}: needs a tanh MLP with squash=True and no feature/action maps, "
                         f"got {spec} (train it with python -m training.imitate --squash true)")
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
    """``path`` relative to the run folder ``root`` where it lies inside it (folders move)."""
    try:
        return str(path.resolve().relative_to(root.resolve()))
    except ValueError:
        return str(path)


def run(cfg: BenchMARLConfig) -> Path:
    """Train, export the actor to ``out_dir`` and evaluate it; returns ``out_dir``."""
    import satenv
    from training.envs import policy_env_meta
    from training.evaluate import evaluate
    from training.policy import LearnedPolicy, ObsNormalizer, save_artifacts

    out = Path(cfg.out_dir)
    experiment = build_experiment(cfg)
    env = satenv.make(cfg.env_id, **cfg.env_kwargs)
    if cfg.init_actor:
        seed_actor(experiment.policy, cfg.init_actor, cfg.init_std, len(env.possible_agents))
    experiment.run()
    agent = env.possible_agents[0]
    obs_dim, act_dim = env.observation_space(agent).shape[0], env.action_space(agent).shape[0]
    actor = export_actor(experiment.policy, obs_dim, act_dim, len(env.possible_agents))
    meta = {**policy_env_meta(cfg.env_id, env, cfg.env_kwargs, cfg.env_kwargs),
            "step": int(experiment.total_frames), "benchmarl_folder": _relative(Path(experiment.folder_name), out)}
    policy = LearnedPolicy(actor, ObsNormalizer(), obs_shape=(obs_dim,), meta=meta)
    config = {**asdict(cfg), "net_arch": list(cfg.net_arch), "eval_seeds": list(cfg.eval_seeds)}
    evaluation = evaluate(env, policy, cfg.eval_seeds) if cfg.eval_seeds else None
    save_artifacts(out, policy, env_meta=meta, config=config, source=f"BenchMARL {cfg.algorithm.upper()}",
                   evaluation=None if evaluation is None else {"eval_seeds": list(cfg.eval_seeds),
                                                               "learned": evaluation["aggregate"]})
    return out


def parse_args(argv: list[str] | None = None) -> BenchMARLConfig:
    d = BenchMARLConfig()
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--algorithm", default=d.algorithm, choices=ALGORITHMS, help=f"(default: {d.algorithm})")
    p.add_argument("--env-id", default=d.env_id, help=f"(default: {d.env_id})")
    p.add_argument("--env-kwargs", default="{}", metavar="JSON", help="env keyword arguments (default: {})")
    for name in ("max_frames", "frames_per_batch", "num_envs", "minibatch_size", "minibatch_iters", "seed",
                 "checkpoint_every"):
        p.add_argument(f"--{name.replace('_', '-')}", type=int, default=getattr(d, name),
                       help=f"(default: {getattr(d, name)})")
    p.add_argument("--lr", type=float, default=d.lr, help=f"(default: {d.lr})")
    p.add_argument("--gamma", type=float, default=d.gamma, help=f"(default: {d.gamma})")
    p.add_argument("--net-arch", default="64,64", help="hidden sizes of actor and critic (default: 64,64)")
    p.add_argument("--eval-seeds", default="10000,10001,10002", help="seeds of eval.json ('' for none)")
    p.add_argument("--out-dir", default=d.out_dir, help=f"(default: {d.out_dir})")
    p.add_argument("--init-actor", default="", metavar="FOLDER",
                   help="start the actor from this policy folder (python -m training.imitate --squash true; "
                        "same --net-arch) instead of at random")
    p.add_argument("--init-std", type=float, default=d.init_std,
                   help=f"the seeded actor's initial action standard deviation (default: {d.init_std})")
    ns = p.parse_args(argv)
    try:
        env_kwargs = json.loads(ns.env_kwargs)
        arch = tuple(int(x) for x in ns.net_arch.split(",") if x)
        seeds = tuple(int(x) for x in ns.eval_seeds.split(",") if x)
    except ValueError as err:
        p.error(f"--env-kwargs must be a JSON object, --net-arch and --eval-seeds comma-separated ints ({err})")
    kw = {k: v for k, v in vars(ns).items() if k not in ("env_kwargs", "net_arch", "eval_seeds")}
    return BenchMARLConfig(env_kwargs=env_kwargs, net_arch=arch, eval_seeds=seeds, **kw)


def main(argv: list[str] | None = None) -> Path:
    try:
        cfg = parse_args(argv)
        import benchmarl  # noqa: F401
    except ImportError as err:
        raise SystemExit(f"error: training.benchmarl_train needs the marl extra ({err}): "
                         "pip install -c constraints.txt -e '.[marl]'") from None
    except ValueError as err:
        raise SystemExit(f"error: {err}") from None
    try:
        out = run(cfg)
    except ValueError as err:
        raise SystemExit(f"error: {err}") from None
    print(f"exported the trained actor to {out} (training.load / benchmarks.scoreboard --policy)")
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
