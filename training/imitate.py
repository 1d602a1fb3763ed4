"""Learn a shared policy by imitating a scripted controller (DAgger), then evaluate it.

    python -m training.imitate --env-id platoon_v0 --env-kwargs '{"preset": "pereira2022", "randomize": true}' \\
        --expert dmpc --out-dir runs/platoon_dagger
    python -m training.imitate --config training/policies/<name>/config.json   # replay a shipped one

DAgger (Ross, Gordon & Bagnell 2011): round 0 lets the expert fly and records its actions; every
later round flies the current network (the expert's action is taken instead with probability
``beta_k = beta ** k`` per step) while the expert labels every visited state with what it would
do there. The network (one MLP shared by every agent, on the agent's own observation: it needs no
privileged state at run time, unlike the expert) is refitted on all labels so far. Read top to
bottom:

1. configuration (:class:`ImitationConfig`; every field is a flag);
2. the expert: ``baselines.make(expert, env, **expert_options)``, privileged (``env.state()``);
3. rounds of data collection and fitting, with a tqdm bar; after each round the network is
   evaluated on ``eval_seeds`` (``eval_history.json``, ``learning_curve.png``) and saved to
   ``rounds/<k>/`` with the dataset (``data.npz``), so ``--resume`` continues after the last
   finished round;
4. artefacts: ``final/`` (the safe policy format of :mod:`training.policy`) with ``eval.json``:
   the network and the named baselines on the held-out ``test_seeds``, ratios against the expert.
"""

from __future__ import annotations

import json
import math
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import tyro

from training.config import (
    Flag,
    Ints,
    JsonDict,
    Names,
    RunConfig,
    check_int,
    check_number,
    check_run_fields,
    parse_args,
)
from training.envs import make_env, policy_env_meta
from training.evaluate import cached_baselines, evaluate, learning_curve, test_summary
from training.policy import LearnedPolicy, ObsNormalizer, save_artifacts

__all__ = ["ImitationConfig", "imitate", "collect_episode", "fit", "main"]


@dataclass(frozen=True)
class ImitationConfig(RunConfig):
    """One imitation (DAgger) run (``python -m training.imitate``)."""

    expert: str = "dmpc"
    """The scripted controller imitated (a name of ``baselines.BASELINES``)."""
    expert_options: JsonDict = field(default_factory=dict)
    """Its config options, a JSON object (``baselines.make(expert, env, **expert_options)``)."""
    rounds: int = 8
    """DAgger rounds (round 0 is the expert's own flights)."""
    episodes_per_round: int = 8
    """Episodes per round, on seeds ``train_seed + episode index``."""
    beta: float = 0.5
    """The expert's action is flown in round k with probability ``beta ** k``."""
    train_seed: int = 100_000
    """First seed of the training episodes (disjoint from the evaluation seeds)."""
    net_arch: Ints = (256, 256)
    """Hidden layer sizes of the MLP."""
    activation: Literal["tanh", "relu", "elu", "silu"] = "tanh"
    """The MLP's activation."""
    squash: Flag = False
    """``tanh`` on the output, as BenchMARL's policies (so the network can seed a BenchMARL
    fine-tune: ``training.benchmarl_train --init-actor``)."""
    epochs: int = 20
    """Regression epochs (mean squared error on the actions, Adam) after each round, warm-started."""
    batch_size: int = 512
    """Regression minibatch size."""
    lr: float = 1e-3
    """Learning rate of the regression."""
    weight_decay: float = 0.0
    """Adam weight decay."""
    clip_obs: float = 10.0
    """Observation normaliser clip (mean and variance from round 0's data)."""
    eval_baselines: Names = ("zero",)
    """Scripted baselines evaluated beside the learned policy and the expert on the test seeds
    (every reference runs at its default config: ``expert_options`` shape the labels only)."""
    baseline_seeds: int = 0
    """How many of the test seeds (the first ones) the expert and baselines run on (0: all)."""
    out_dir: str = "runs/imitate"
    """Run folder: ``config.json``, ``rounds/<k>/``, ``final/`` (the policy with ``eval.json``)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        check_run_fields(self, ("expert_options",))
        if not isinstance(self.expert, str) or not self.expert:
            raise ValueError(f"expert must be a baseline name such as 'dmpc', got {self.expert!r}")
        for name in ("rounds", "episodes_per_round", "epochs", "batch_size"):
            check_int(name, getattr(self, name), minimum=1)
        for name in ("train_seed", "baseline_seeds"):
            check_int(name, getattr(self, name), minimum=0)
        if isinstance(self.beta, bool) or not isinstance(self.beta, (int, float)) or not 0 <= self.beta <= 1:
            raise ValueError(f"beta must be a number in [0, 1], got {self.beta!r}")
        check_number("clip_obs", self.clip_obs, 0.0, math.inf)
        if not (isinstance(self.weight_decay, (int, float)) and 0 <= self.weight_decay < math.inf):
            raise ValueError(f"weight_decay must be a finite number >= 0, got {self.weight_decay!r}")
        from training.actor import ACTIVATIONS

        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {sorted(ACTIVATIONS)}, got {self.activation!r}")
        if not isinstance(self.squash, bool):
            raise ValueError(f"squash must be a bool, got {self.squash!r}")


# --------------------------------------------------------------------------- data
def collect_episode(env: Any, expert: Any, learner: LearnedPolicy | None, seed: int, beta: float,
                    rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One episode: every visited observation and the expert's action there, ``(rows, obs_dim)``
    and ``(rows, act_dim)``. The expert's action is flown with probability ``beta`` per step
    (always without a ``learner``), the learner's otherwise."""
    obs, _ = env.reset(seed=seed)
    expert.reset(seed=seed)
    xs, ys = [], []
    while env.agents:
        labels = expert.act(obs)
        agents = list(obs)
        xs.append(np.stack([obs[a] for a in agents]))
        ys.append(np.stack([np.asarray(labels[a], dtype=np.float64) for a in agents]))
        flown = labels if learner is None or rng.random() < beta else learner.act(obs)
        obs, *_ = env.step(flown)
    return np.concatenate(xs), np.clip(np.concatenate(ys), -1.0, 1.0)


def fit(actor: Any, normalizer: ObsNormalizer, x: np.ndarray, y: np.ndarray, cfg: ImitationConfig,
        generator: Any) -> float:
    """Regress ``actor`` on ``(x, y)`` for ``cfg.epochs`` epochs; returns the last epoch's mean loss."""
    return regress(actor, normalizer(x), y, lr=cfg.lr, epochs=cfg.epochs, batch_size=cfg.batch_size,
                   generator=generator, weight_decay=cfg.weight_decay)


def regress(actor: Any, x: np.ndarray, y: np.ndarray, *, lr: float, epochs: int, batch_size: int,
            generator: Any, weight_decay: float = 0.0) -> float:
    """Adam on the mean squared error of ``actor(x)`` against ``y`` (``x`` already normalised),
    shuffled minibatches from ``generator``; returns the last epoch's mean loss."""
    import torch

    xt, yt = torch.as_tensor(x), torch.as_tensor(y, dtype=torch.float32)
    opt = torch.optim.Adam(actor.parameters(), lr=lr, weight_decay=weight_decay)
    actor.train()
    loss_sum = 0.0
    for _ in range(epochs):
        loss_sum = 0.0
        for idx in torch.randperm(len(xt), generator=generator).split(batch_size):
            loss = torch.mean((actor(xt[idx]) - yt[idx]) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
            loss_sum += loss.item() * len(idx)
    actor.eval()
    return loss_sum / len(xt)


# --------------------------------------------------------------------------- run
def imitate(cfg: ImitationConfig, resume: bool = False) -> Path:
    """Run (or resume) DAgger; returns the ``final/`` artefact folder."""
    import torch

    import baselines
    from training.actor import MLPActor

    out = Path(cfg.out_dir)
    done = _finished_rounds(out)
    if not resume and done:
        raise ValueError(f"{out} already has rounds; pass --resume to continue or choose another --out-dir")
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(json.dumps(cfg.to_json(), indent=2) + "\n")
    torch.set_num_threads(cfg.torch_threads)
    torch.manual_seed(cfg.seed)
    generator = torch.Generator().manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)

    env = make_env(cfg.env_id, **cfg.env_kwargs)
    eval_env = make_env(cfg.env_id, **cfg.resolved_eval_env_kwargs)
    expert = baselines.make(cfg.expert, env, **cfg.expert_options)
    meta = policy_env_meta(cfg.env_id, env, cfg.env_kwargs, cfg.resolved_eval_env_kwargs)
    agent = env.possible_agents[0]
    obs_dim, act_dim = env.observation_space(agent).shape[0], env.action_space(agent).shape[0]
    actor = MLPActor(obs_dim, act_dim, list(cfg.net_arch), cfg.activation, cfg.squash)
    names = list(dict.fromkeys([cfg.expert, *cfg.eval_baselines]))
    key = {"env_id": cfg.env_id, "eval_env_kwargs": cfg.resolved_eval_env_kwargs}  # baselines at their defaults
    opts = {"progress": cfg.progress, "workers": cfg.workers}
    expert_eval = cached_baselines(out / "baselines_eval.json", eval_env, [cfg.expert], cfg.eval_seeds, key, **opts)

    data, normalizer, history = _restore(out, done, actor) if done else ({"x": [], "y": []}, None, [])
    bar = _bar(cfg, done)
    t0 = time.perf_counter()
    for k in range(done, cfg.rounds):
        learner = None if k == 0 else LearnedPolicy(actor, normalizer, obs_shape=(obs_dim,), meta=meta)
        for e in range(cfg.episodes_per_round):
            x, y = collect_episode(env, expert, learner, cfg.train_seed + k * cfg.episodes_per_round + e,
                                   cfg.beta ** k, rng)
            data["x"].append(x)
            data["y"].append(y)
            bar.update(1)
        x_all, y_all = np.concatenate(data["x"]), np.concatenate(data["y"])
        if normalizer is None:
            normalizer = ObsNormalizer(x_all.mean(0), x_all.var(0), cfg.clip_obs)
        loss = fit(actor, normalizer, x_all, y_all, cfg, generator)
        policy = LearnedPolicy(actor, normalizer, obs_shape=(obs_dim,), meta=meta)
        agg = evaluate(eval_env, policy, cfg.eval_seeds, desc=f"evaluation, round {k}", **opts)["aggregate"]
        history.append({"round": k, "labels": int(len(x_all)), "loss": loss, "beta": cfg.beta ** k,
                        "wall_s": round(time.perf_counter() - t0, 1), "aggregate": agg})
        bar.set_postfix(round=k, loss=f"{loss:.4f}", success=f"{agg['success_rate']:.2f}",
                        rmse=f"{agg['rmse']:.3g}")
        _save_round(out, k, policy, meta, cfg, data, history)
        learning_curve(history, expert_eval.get(cfg.expert), cfg.expert, out / "learning_curve.png")
    bar.close()

    policy = LearnedPolicy(actor, normalizer, obs_shape=(obs_dim,), meta=meta)
    base_seeds = cfg.test_seeds[:cfg.baseline_seeds] if cfg.baseline_seeds else cfg.test_seeds
    test_baselines = cached_baselines(out / "baselines_test.json", eval_env, names, base_seeds, key, **opts)
    summary = test_summary(eval_env, policy, test_baselines, cfg.test_seeds, reference=cfg.expert, **opts,
                           labels=int(sum(len(x) for x in data["x"])), rounds=cfg.rounds,
                           train_wall_s_this_session=round(time.perf_counter() - t0, 1))
    final = save_artifacts(out / "final", policy, env_meta={**meta, "rounds": cfg.rounds},
                           config=cfg.to_json(), evaluation=summary,
                           source=f"DAgger imitation of baselines '{cfg.expert}' (training.imitate)")
    if (out / "learning_curve.png").is_file():
        (final / "learning_curve.png").write_bytes((out / "learning_curve.png").read_bytes())
    print(f"final policy after {cfg.rounds} rounds on {len(cfg.test_seeds)} held-out seeds:\n{summary['table']}")
    return final


def _bar(cfg: ImitationConfig, done: int):
    from tqdm.auto import tqdm

    total = cfg.rounds * cfg.episodes_per_round
    return tqdm(total=total, initial=done * cfg.episodes_per_round, desc="DAgger episodes",
                disable=not cfg.progress, file=sys.stderr)


def _finished_rounds(out: Path) -> int:
    path = out / "eval_history.json"
    return len(json.loads(path.read_text())) if path.is_file() else 0


def _save_round(out: Path, k: int, policy: LearnedPolicy, meta: dict[str, Any], cfg: ImitationConfig,
                data: dict[str, list[np.ndarray]], history: list[dict[str, Any]]) -> None:
    save_artifacts(out / "rounds" / str(k), policy, env_meta={**meta, "rounds": k + 1}, config=cfg.to_json(),
                   source="training.imitate round checkpoint")
    np.savez_compressed(out / "data.npz", x=np.concatenate(data["x"]), y=np.concatenate(data["y"]),
                        lengths=np.array([len(x) for x in data["x"]]))
    (out / "eval_history.json").write_text(json.dumps(history, indent=1) + "\n")


def _restore(out: Path, done: int, actor: Any):
    """Dataset, normaliser and history after the last finished round (``--resume``)."""
    from training.policy import load

    last = load(out / "rounds" / str(done - 1))
    actor.load_state_dict(last.actor.state_dict())
    with np.load(out / "data.npz", allow_pickle=False) as d:
        x, y, lengths = d["x"], d["y"], d["lengths"]
    cuts = np.cumsum(lengths)[:-1]
    data = {"x": np.split(x, cuts), "y": np.split(y, cuts)}
    return data, last.normalizer, json.loads((out / "eval_history.json").read_text())


# --------------------------------------------------------------------------- CLI
def main(argv: list[str] | None = None) -> Path:
    try:
        cfg, opts = parse_args(argv, cls=ImitationConfig, resume=True, prog="python -m training.imitate",
                               description=__doc__.split("\n\n")[0])
        return imitate(cfg, resume=opts.resume)
    except ValueError as err:
        raise SystemExit(f"error: {err}") from None


if __name__ == "__main__":
    warnings.filterwarnings("ignore", category=DeprecationWarning)
    main()
