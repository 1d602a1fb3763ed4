"""DAgger of a system's stateless expert on its training task, resumable (one driver for every
system of :data:`satenv.tasks.SYSTEMS`).

    nice -n 5 env OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python -m training.recipes.dagger --system platoon-pereira2022 --run-dir runs/p22/dagger
    nice -n 5 env OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python -m training.recipes.dagger --system cluster-li2022 --run-dir runs/cluster/dagger

The same command resumes a run at any time: labels go to ``<run>/labels/round_NNNN.npz``
(observations, expert actions, the env state, agent and step of every row), the network to
``<run>/rounds/NNNN/`` (the policy folder format of :mod:`training.policy`) after each round, with
``history.json`` and ``learning_curve.png``. Restarting with the same ``--run-dir`` continues
after the last finished round (``config.json`` of the run; flags given again override it).

Recipe (read top to bottom):

1. expert (the system's, ``training.experts.make``): re-planned from the current state at every decision, so its label in
   a state the learner flew into is what it would do there — :class:`training.experts.JointPlatoonMPC`
   (pereira2022 §5.1, sequential coupling: follower j's action depends only on followers 1..j,
   which its PLF observation holds) or :class:`training.experts.ReplanningTubeRDMPC` (li2022);
2. round 0: the expert flies (a share of episodes with Gaussian action noise, DART-style); each
   later round the network flies (the expert's action is flown with probability ``beta ** k``)
   and the expert labels every visited state; collisions do not end collection episodes;
   a share of episodes starts from the paper's initial state;
3. the network (one MLP shared by every agent, own observation only; the clock entry is zeroed
   and symlog features of the tracking error appended, :class:`training.shaping.ObsFeatures`)
   is refitted on all labels after every round (warm start) and evaluated on validation seeds
   (``val_seeds``, in the validation split; episodes are collected on train seeds from
   ``train_seed``; the test split is never touched).
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from satenv import scoring, tasks
from training.recipes import system_name

__all__ = ["DaggerConfig", "run", "main"]

SYSTEM_DEFAULTS: dict[str, dict[str, Any]] = {
    "platoon-pereira2022": {},
    "cluster-li2022": {"round0_episodes": 6, "episodes_per_round": 4, "val_seeds": (700_000, 700_001, 700_002),
                       "expert_options": {}, "obs_drop_dims": (18,), "obs_symlog_scale": 300.0,
                       "noise_std": 0.1, "epochs": 20},
    # the cooperative NMPC (N = 30) warm-starts and plans against the other spacecraft's previous
    # plan, so its shadow labels are close to, not exactly, what it would do
    # (training/runs/servicing_pereira2022_dagger)
    "servicing-pereira2022": {"round0_episodes": 4, "episodes_per_round": 2,
                              "val_seeds": (700_000, 700_001, 700_002), "expert_options": {},
                              "obs_drop_dims": (), "obs_symlog_scale": 10.0, "noise_std": 0.05, "epochs": 20},
    # C/GMRES continues its previous solution and the pereira2023 DMPC warm-starts, so neither is a
    # stateless expert: these run, but their labels are the shadow plans' (see the module docstring)
    "formation-kannan2022-collision": {"expert_options": {}, "obs_drop_dims": (),
                                       "val_seeds": (700_000, 700_001, 700_002)},
    "formation-kannan2022-position": {"expert_options": {}, "obs_drop_dims": (),
                                      "val_seeds": (700_000, 700_001, 700_002)},
    "platoon-pereira2023": {"expert_options": {}, "obs_drop_dims": (14,),
                            "val_seeds": (700_000, 700_001, 700_002)},
}
"""This recipe's hyper-parameters per system of :data:`satenv.tasks.SYSTEMS` (the env, the expert and
the seeds come from the task registry: the system's training and paper tasks)."""


@dataclass(frozen=True)
class DaggerConfig:
    """One DAgger run (every field is a ``--flag``)."""

    system: str = "platoon-pereira2022"
    """A system of :data:`satenv.tasks.SYSTEMS` (old names: :data:`training.recipes.LEGACY_SYSTEM_NAMES`)."""
    learner_shield: bool = False
    rounds: int = 1000
    round0_episodes: int = 40
    episodes_per_round: int = 16
    beta: float = 0.5
    noise_share: float = 0.5
    noise_std: float = 0.15
    paper_start_share: float = 0.2
    train_seed: int = 600_000
    val_seeds: tuple[int, ...] = tuple(range(700_000, 700_012))
    expert_options: dict[str, Any] = field(default_factory=lambda: {"coupling": "sequential"})
    net_arch: tuple[int, ...] = (512, 512, 512)
    activation: str = "relu"
    squash: bool = True
    obs_drop_dims: tuple[int, ...] = (14,)
    obs_symlog_scale: float = 20.0
    obs_symlog_dims: int = 6
    epochs: int = 6
    batch_size: int = 1024
    learning_rate: float = 5e-4
    clip_obs: float = 10.0
    seed: int = 0
    terminal: dict[str, Any] = field(default_factory=dict)   # training.shaping.TerminalFeedback fields

    def to_json(self) -> dict[str, Any]:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


# --------------------------------------------------------------------------- pieces
def make_envs(system: tasks.System):
    """Collection envs (the training task's random starts and the paper task's start, collisions do
    not end them) and the evaluation envs of the same two tasks."""
    train, paper = tasks.get(system.training_task), tasks.get(system.paper_task)
    return (train.make_env(terminate_on_collision=False), paper.make_env(terminate_on_collision=False),
            train.make_env(), paper.make_env())


def make_expert(system: tasks.System, env, options: dict[str, Any]):
    from training.experts import make

    return make(system.expert, env, **options)


def features(cfg: DaggerConfig):
    from training.shaping import ObsFeatures

    return ObsFeatures(cfg.obs_symlog_scale, cfg.obs_symlog_dims, tuple(cfg.obs_drop_dims))


def collect_episode(env, expert, learner, seed: int, beta: float, noise: float,
                    rng: np.random.Generator) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """One episode: every visited observation with the expert's label, the env state and agent;
    and how the flown episode ended (final position error, collision, closest approach)."""
    obs, _ = env.reset(seed=seed)
    expert.reset(seed=seed)
    if learner is not None:
        learner.reset(seed=seed)
    rows: dict[str, list] = {"obs": [], "act": [], "state": [], "agent": [], "t": []}
    t, collided, min_sep, infos = 0, False, np.inf, {}
    while env.agents:
        agents = list(obs)
        state = np.asarray(env.state(), dtype=np.float64)
        labels = expert.act(obs)
        for a in agents:
            rows["obs"].append(obs[a])
            rows["act"].append(labels[a])
            rows["state"].append(state)
            rows["agent"].append(int(a.rsplit("_", 1)[1]) - 1)
            rows["t"].append(t)
        if learner is None or rng.random() < beta:
            flown = labels
        else:
            flown = learner.act(obs)
        if noise > 0:
            flown = {a: np.clip(v + rng.normal(0, noise, np.shape(v)), -1, 1).astype(np.float32) for a, v in flown.items()}
        obs, _, _, _, infos = env.step(flown)
        collided |= any(bool(i["collision"]) for i in infos.values())
        min_sep = min(min_sep, *(float(i["min_separation"]) for i in infos.values()))
        t += 1
    final = max(float(np.linalg.norm(np.asarray(i["tracking_error"])[:3])) for i in infos.values())
    stats = {"seed": seed, "steps": t, "final_error_m": round(final, 4), "collision": collided,
             "min_separation_m": round(min_sep, 3), "learner": learner is not None, "noise": noise}
    return {k: np.asarray(v, dtype=np.float32 if k in ("obs", "act") else None) for k, v in rows.items()}, stats


def load_labels(run: Path, rounds: int) -> tuple[np.ndarray, np.ndarray]:
    """The observations and clipped expert actions of rounds ``0 .. rounds - 1`` (the rounds
    ``history.json`` records as complete; a label file of a later, unfinished round is ignored)."""
    from training.runfolder import RunFolderError

    xs, ys = [], []
    for k in range(rounds):
        path = label_path(run, k)
        try:
            with np.load(path, allow_pickle=False) as d:
                xs.append(d["obs"])
                ys.append(d["act"])
        except (OSError, KeyError, ValueError) as err:
            raise RunFolderError(f"{path}: the labels of round {k}, recorded complete in history.json, cannot be "
                                 f"read ({type(err).__name__}: {str(err)[:80]})") from None
    if not xs:
        return np.zeros((0, 1)), np.zeros((0, 3))
    return np.concatenate(xs), np.clip(np.concatenate(ys), -1, 1)


def label_path(run: Path, k: int) -> Path:
    """Where round ``k``'s labels are saved."""
    return run / "labels" / f"round_{k:04d}.npz"


def read_history(run: Path) -> list[dict[str, Any]]:
    """The complete rounds of a run (``history.json``, written last in each round: the run's record
    of progress); ``[]`` for a new run. A malformed file is a :class:`training.runfolder.RunFolderError`."""
    from training.runfolder import RunFolderError, read_json

    path = run / "history.json"
    if not path.exists():
        return []
    history = read_json(path, "a list of finished DAgger rounds")
    if not isinstance(history, list) or any(not isinstance(h, dict) or h.get("round") != k
                                            for k, h in enumerate(history)):
        raise RunFolderError(f"{path}: expected a list of rounds 0, 1, ... (objects with 'round'), got "
                             f"{str(history)[:80]}")
    return history


def fit(actor, normalizer, feats, x, y, cfg: DaggerConfig, generator, epochs: int) -> float:
    """:func:`training.imitate.regress` on the features of ``x``."""
    from training.imitate import regress

    return regress(actor, normalizer(feats(x.astype(np.float64))), y, lr=cfg.learning_rate, epochs=epochs,
                   batch_size=cfg.batch_size, generator=generator)


def evaluate(env, policy, seeds) -> dict[str, Any]:
    """:func:`satenv.scoring.aggregate` of the episodes on ``seeds``."""
    return scoring.aggregate(scoring.run_episodes(env, policy, seeds))


def plot_curve(history: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [h["labels"] for h in history]
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.6))
    ax[0].plot(labels, [h["val"]["success_rate"] for h in history], "o-", label="random starts")
    ax[0].plot(labels, [h["paper"]["success_rate"] for h in history], "s--", label="paper start")
    if any("shield" in h for h in history):
        sh = [(h["labels"], h["shield"]["val"]) for h in history if "shield" in h]
        ax[0].plot([a for a, _ in sh], [v["success_rate"] for _, v in sh], "^-", label="random, +shield")
        ax[1].plot([a for a, _ in sh], [v["collision_episodes"] for _, v in sh], "^-", label="+shield")
    ax[0].set_ylabel("success rate")
    ax[0].legend()
    ax[1].plot(labels, [h["val"]["collision_episodes"] for h in history], "o-", label="network")
    ax[1].set_ylabel(f"collision episodes (of {history[-1]['val']['episodes']})")
    ax[1].legend()
    ax[2].semilogy(labels, [h["loss"] for h in history], "o-")
    ax[2].set_ylabel("regression MSE")
    for a in ax:
        a.set_xlabel("expert labels (agent-steps)")
        a.grid(alpha=0.3)
    fig.suptitle(f"DAgger, {history[-1].get('system', '')} (validation seeds)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


# --------------------------------------------------------------------------- run
def run(cfg: DaggerConfig, run_dir: Path) -> None:
    import torch

    from satenv.safety import shield
    from training import runfolder
    from training.actor import MLPActor
    from training.envs import policy_env_meta
    from training.policy import (
        LearnedPolicy,
        ObsNormalizer,
        load,
        save_artifacts,
        terminal_from_config,
    )

    torch.set_num_threads(1)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "labels").mkdir(exist_ok=True)
    runfolder.write_json(run_dir / "config.json", cfg.to_json(), indent=2)
    system = tasks.system(cfg.system)
    train_task = tasks.get(system.training_task)
    wrong = [s for s in cfg.val_seeds if train_task.split_of(s) != "validation"]
    if wrong or train_task.split_of(cfg.train_seed) != "train":
        raise SystemExit(f"error: val_seeds must be validation seeds and train_seed a train seed "
                         f"(satenv.tasks.SEED_SPLITS); got val_seeds {wrong[:3]}..., train_seed {cfg.train_seed}")
    collect, paper, ev, paper_ev = make_envs(system)
    experts = {id(collect): make_expert(system, collect, cfg.expert_options),
               id(paper): make_expert(system, paper, cfg.expert_options)}
    feats = features(cfg)
    term = terminal_from_config(cfg.to_json())      # part of the learner, as at inference
    obs_dim = collect.observation_space(collect.possible_agents[0]).shape[0]
    meta = policy_env_meta(train_task.env_id, collect, {**train_task.env_kwargs, "terminate_on_collision": False},
                           dict(train_task.env_kwargs))
    policy_cfg = {**cfg.to_json(), "recipe": "training.recipes.dagger", "expert": system.expert}
    history_path = run_dir / "history.json"
    history = read_history(run_dir)          # resume after the last round it records, never by counting files
    done = len(history)
    x, y = load_labels(run_dir, done)
    act_dim = collect.action_space(collect.possible_agents[0]).shape[0]
    torch.manual_seed(cfg.seed)              # the initial weights: the same in every session
    actor = MLPActor(feats.out_dim(obs_dim), act_dim, list(cfg.net_arch), cfg.activation, cfg.squash)
    normalizer = None
    if history:
        runfolder.recover_folder(round_folder(run_dir, done - 1))   # a swap a kill interrupted
        last = load(round_folder(run_dir, done - 1))
        actor.load_state_dict(last.actor.state_dict())
        normalizer = last.normalizer
    t_start = time.perf_counter()
    episode = sum(cfg.round0_episodes if k == 0 else cfg.episodes_per_round for k in range(done))
    for k in range(done, cfg.rounds):
        # every round's randomness from (seed, round): a resumed run flies exactly the rounds of an
        # uninterrupted one
        generator = torch.Generator().manual_seed(cfg.seed + k)
        rng = np.random.default_rng([cfg.seed, k])
        net = None if k == 0 else LearnedPolicy(actor, normalizer, obs_shape=(obs_dim,), features=feats,
                                                terminal=term)
        learners = {id(e): (shield(net, e) if cfg.learner_shield and net is not None else net)
                    for e in (collect, paper)}
        n_eps = cfg.round0_episodes if k == 0 else cfg.episodes_per_round
        parts, flown = [], []
        t0 = time.perf_counter()
        for _ in range(n_eps):
            env = paper if rng.random() < cfg.paper_start_share else collect
            noise = cfg.noise_std if (k == 0 and rng.random() < cfg.noise_share) else 0.0
            part, stats = collect_episode(env, experts[id(env)], learners[id(env)], cfg.train_seed + episode,
                                          cfg.beta ** k, noise, rng)
            parts.append(part)
            flown.append({**stats, "paper_start": env is paper})
            print(f"  episode {json.dumps(flown[-1])} at {time.perf_counter() - t0:.0f}s", flush=True)
            episode += 1
        batch = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
        runfolder.save_with(label_path(run_dir, k), lambda tmp: _savez(tmp, batch))  # noqa: B023 - called at once
        collect_s = time.perf_counter() - t0
        x = batch["obs"] if len(x) == 0 else np.concatenate([x, batch["obs"]])
        y = np.clip(batch["act"], -1, 1) if len(y) == 0 else np.concatenate([y, np.clip(batch["act"], -1, 1)])
        if normalizer is None:
            fx = feats(x.astype(np.float64))
            normalizer = ObsNormalizer(fx.mean(0), fx.var(0), cfg.clip_obs)
        t1 = time.perf_counter()
        loss = fit(actor, normalizer, feats, x, y, cfg, generator, cfg.epochs * (4 if k == 0 else 1))
        fit_s = time.perf_counter() - t1
        policy = LearnedPolicy(actor, normalizer, obs_shape=(obs_dim,), features=feats, meta=meta, terminal=term)
        paper_seeds = tasks.get(system.paper_task).seeds("validation", 1)
        val, pap = evaluate(ev, policy, cfg.val_seeds), evaluate(paper_ev, policy, paper_seeds)
        if cfg.learner_shield:
            shielded = {"val": evaluate(ev, shield(policy, ev), cfg.val_seeds),
                        "paper": evaluate(paper_ev, shield(policy, paper_ev), paper_seeds)}
        history.append({"system": cfg.system, "round": k, "labels": int(len(x)), "episodes": episode, "loss": loss,
                        "beta": cfg.beta ** k, "collect_s": round(collect_s, 1), "fit_s": round(fit_s, 1),
                        "session_wall_s": round(time.perf_counter() - t_start, 1), "val": val, "paper": pap, "collected": flown,
                        **({"shield": shielded} if cfg.learner_shield else {})})
        # the round's files, each whole or absent, then history.json: the round is complete
        staged = runfolder.staging(round_folder(run_dir, k))
        save_artifacts(staged, policy, env_meta=meta, config=policy_cfg, source="training.recipes.dagger round checkpoint")
        runfolder.replace_folder(staged, round_folder(run_dir, k))
        runfolder.write_json(history_path, history)
        runfolder.save_with(run_dir / "learning_curve.png", lambda tmp: plot_curve(history, tmp))  # noqa: B023
        if cfg.learner_shield:
            print(f"  +shield: val success {shielded['val']['success_rate']:.2f} coll "
                  f"{shielded['val']['collision_episodes']} fe {shielded['val']['final_error_m']:.2f}", flush=True)
        print(f"round {k}: labels {len(x)} loss {loss:.4f} val success {val['success_rate']:.2f} "
              f"coll {val['collision_episodes']} fe {val['final_error_m']:.2f} paper {pap['success_rate']:.0f} "
              f"collect {collect_s:.0f}s fit {fit_s:.0f}s", flush=True)


def round_folder(run: Path, k: int) -> Path:
    """Round ``k``'s policy folder."""
    return run / "rounds" / f"{k:04d}"


def _savez(path: Path, arrays: dict[str, np.ndarray]) -> None:
    with open(path, "wb") as fh:     # a file object: numpy adds no ".npz" to the temporary name
        np.savez_compressed(fh, **arrays)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--run-dir", required=True, type=Path)
    parser.add_argument("--system", default=None, help=f"one of {', '.join(SYSTEM_DEFAULTS)}")
    for f in DaggerConfig.__dataclass_fields__.values():
        if f.name != "system":
            parser.add_argument("--" + f.name.replace("_", "-"), type=str, default=None,
                                help="a JSON value")
    ns = parser.parse_args(argv)
    saved = ns.run_dir / "config.json"
    if saved.is_file():
        from training.runfolder import RunFolderError, read_json

        try:
            base = _config(read_json(saved, "the run's DaggerConfig"))
        except (RunFolderError, TypeError, ValueError) as err:
            raise SystemExit(f"error: cannot resume {ns.run_dir}: {str(err)[:300]}") from None
    else:
        name = system_name(ns.system or DaggerConfig.system)
        if name not in SYSTEM_DEFAULTS:
            raise SystemExit(f"error: --system must be one of {sorted(SYSTEM_DEFAULTS)}, got {name!r}")
        base = _config({"system": name, **SYSTEM_DEFAULTS[name]})
    over = {k: (system_name(v) if k == "system" else json.loads(v)) for k, v in vars(ns).items()
            if k != "run_dir" and v is not None}
    cfg = replace(base, **_config_fields({**over, "system": system_name(over.get("system", base.system))}))
    if cfg.system not in SYSTEM_DEFAULTS:
        raise SystemExit(f"error: system must be one of {sorted(SYSTEM_DEFAULTS)}, got {cfg.system!r}")
    from training.policy import PolicyLoadError
    from training.runfolder import RunFolderError

    try:
        run(cfg, ns.run_dir)
    except (RunFolderError, PolicyLoadError) as err:      # a malformed run folder: named, no traceback
        raise SystemExit(f"error: cannot resume {ns.run_dir}: {str(err)[:400]}") from None


def _config_fields(d: dict[str, Any]) -> dict[str, Any]:
    return {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}


def _config(d: dict[str, Any]) -> DaggerConfig:
    return DaggerConfig(**_config_fields(d))


if __name__ == "__main__":
    main()
