"""DAgger: learn a shared policy by imitating an expert, resumable after a kill (the one DAgger of
the project; ``python -m satenv.training.recipes.dagger`` is the same engine and grammar).

    python -m satenv.training.imitate --task platoon-pereira2022-random --rounds 8 --out-dir runs/platoon_dagger
    python -m satenv.training.imitate --env-id formation_v0 --expert cgmres --rounds 4 --out-dir runs/formation_dagger
    python -m satenv.training.imitate --out-dir runs/platoon_dagger --rounds 12 --resume   # continue a run
    python -m satenv.training.imitate --config satenv/training/policies/<name>/config.json        # replay a shipped one

DAgger (Ross, Gordon & Bagnell 2011): round 0 lets the expert fly (a share of its episodes with
Gaussian action noise, DART-style) and records its actions; every later round flies the current
network (the expert's action is taken instead with probability ``beta ** k`` per step) while the
expert labels every visited state with what it would do there. The network (one MLP shared by
every agent, on the agent's own observation and :class:`satenv.training.shaping.ObsFeatures` of it: no
privileged state at run time, unlike the expert) is refitted on all labels after every round (warm
start) and evaluated on ``eval_seeds``. Read top to bottom:

1. configuration (:class:`DaggerConfig`, every field a flag of the :mod:`satenv.training.config` grammar;
   a task of a system of :data:`satenv.tasks.SYSTEMS` brings :data:`SYSTEM_DEFAULTS`, the
   system's expert and its paper task, whose start a share of episodes flies from);
2. the expert (``satenv.baselines.experts.make``: a stateless expert of ``satenv.baselines.experts.EXPERTS`` or
   any scripted baseline), privileged (``env.state()``);
3. rounds of collection and fitting; each round's files are whole or absent
   (:mod:`satenv.training.runfolder`): labels to ``labels/round_NNNN.npz`` (observations, expert
   actions, env state, agent and step of every row), the network to ``rounds/NNNN/`` (the policy
   folder of :mod:`satenv.training.policy`), then ``history.json``, written last: a run resumes after the
   last round it records (``--resume``), and every round's randomness comes from ``(seed, round)``,
   so a resumed run equals an uninterrupted one;
4. ``final/`` (a policy folder with ``eval.json``: the network and the named baselines on the
   held-out ``test_seeds``, ratios against the reference controller), swapped in whole.
"""

from __future__ import annotations

import json
import math
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple

import numpy as np

from satenv import scoring, tasks
from satenv.training.config import (
    Flag,
    Ints,
    JsonDict,
    Names,
    RunConfig,
    check_int,
    check_number,
    check_run_fields,
    config_from_json,
    parse_args,
)

__all__ = ["DaggerConfig", "ImitationConfig", "SYSTEM_DEFAULTS", "collect_episode", "fit", "main", "regress",
           "run", "system_config"]

_VALIDATION3 = (700_000, 700_001, 700_002)
_PLATOON = {"round0_episodes": 40, "episodes_per_round": 16, "noise_std": 0.15, "obs_symlog_scale": 20.0,
            "epochs": 6}
SYSTEM_DEFAULTS: dict[str, dict[str, Any]] = {
    "platoon-pereira2022": {**_PLATOON, "eval_seeds": tuple(range(700_000, 700_012)),
                            "expert_options": {"coupling": "sequential"}, "obs_drop_dims": (14,)},
    # the reference controllers of the cluster and servicing (tube-RDMPC, NMPC) take minutes an
    # episode: final/'s eval.json runs them on the first test seeds only (the network on all)
    "cluster-li2022": {"round0_episodes": 6, "episodes_per_round": 4, "eval_seeds": _VALIDATION3,
                       "obs_drop_dims": (18,), "obs_symlog_scale": 300.0, "noise_std": 0.1, "epochs": 20,
                       "baseline_seeds": 3},
    # the cooperative NMPC (N = 30) warm-starts and plans against the other spacecraft's previous
    # plan, so its shadow labels are close to, not exactly, what it would do
    # (studies/runs/servicing_pereira2022_dagger)
    "servicing-pereira2022": {"round0_episodes": 4, "episodes_per_round": 2, "eval_seeds": _VALIDATION3,
                              "obs_drop_dims": (), "obs_symlog_scale": 10.0, "noise_std": 0.05, "epochs": 20,
                              "baseline_seeds": 3},
    # C/GMRES continues its previous solution and the pereira2023 DMPC warm-starts, so neither is a
    # stateless expert: these run, but their labels are the shadow plans'
    "formation-kannan2022-collision": {**_PLATOON, "eval_seeds": _VALIDATION3},
    "formation-kannan2022-position": {**_PLATOON, "eval_seeds": _VALIDATION3},
    "platoon-pereira2023": {**_PLATOON, "eval_seeds": _VALIDATION3, "obs_drop_dims": (14,)},
}
"""Hyper-parameters per system of :data:`satenv.tasks.SYSTEMS` (field -> value), applied under the
flags when ``--task`` is one of the system's tasks (the env, the expert and the seeds come from the
task registry)."""

ROUND0_EPOCH_FACTOR = 4
"""Round 0 fits ``round0_epoch_factor`` times ``epochs`` by default (the network starts cold)."""


@dataclass(frozen=True)
class DaggerConfig(RunConfig):
    """One DAgger run (``python -m satenv.training.imitate``, ``python -m satenv.training.recipes.dagger``)."""

    net_arch: Ints = (512, 512, 512)
    """Hidden layer sizes of the MLP (with ``architecture="set"``: of the head after the pooling)."""
    architecture: Literal["mlp", "set"] = "mlp"
    """The network: ``"mlp"`` (every input to one MLP) or ``"set"`` (``satenv.training.set_policy.SetActor``:
    a shared encoder of the neighbour slots, masked mean and max pooling, then the head; the env needs
    the fixed layout, ``env_kwargs`` ``obs_neighbours``), so one network flies any team size."""
    set_encoder: Ints = (64, 64)
    """Hidden sizes of the set actor's per-slot encoder (its last is the pooled code's width)."""
    prior_labels: Names = ()
    """Label files (``labels/round_NNNN.npz`` of another run, ``obs`` and ``act`` of this env's
    observation layout) added to every fit: the expert's labels of an earlier run reused."""
    lr: float = 5e-4
    """Learning rate of the regression (Adam)."""
    out_dir: str = "runs/dagger"
    """Run folder: ``config.json``, ``labels/``, ``rounds/NNNN/``, ``history.json``, ``final/`` (the
    policy with ``eval.json``). ``--run-dir`` is an alias."""
    expert: str | None = None
    """The imitated controller: a stateless expert of ``satenv.baselines.experts.EXPERTS`` or a name of
    ``satenv.baselines.BASELINES`` (default: the expert ``satenv.tasks`` names for the task's system)."""
    expert_options: JsonDict = field(default_factory=dict)
    """Its options, a JSON object (``satenv.baselines.experts.make(expert, env, **expert_options)``)."""
    rounds: int = 8
    """DAgger rounds (round 0: the expert's own flights; 0 builds the envs and experts only)."""
    round0_episodes: int = 8
    """Episodes of round 0 (the expert flies)."""
    episodes_per_round: int = 8
    """Episodes of every later round; episode ``i`` of the run resets with ``train_seed + i``."""
    beta: float = 0.5
    """The expert's action is flown in round k with probability ``beta ** k`` per step."""
    noise_share: float = 0.5
    """Share of round 0's episodes flown with Gaussian action noise (DART)."""
    noise_std: float = 0.15
    """Standard deviation of that noise (actions in [-1, 1])."""
    paper_start_share: float = 0.2
    """Share of episodes started from the system's paper task (its paper start; ignored without one)."""
    collect_through_collisions: Flag = True
    """A collision does not end a collection episode (satenv envs: ``terminate_on_collision=False``)."""
    train_seed: int = 600_000
    """Seed of the first training episode (with a task: in its train split)."""
    activation: Literal["tanh", "relu", "elu", "silu"] = "relu"
    """The MLP's activation."""
    squash: Flag = True
    """``tanh`` on the output, as BenchMARL's policies (the network can seed a BenchMARL fine-tune:
    ``satenv.training.benchmarl_train --init-actor``)."""
    obs_drop_dims: Ints = ()
    """Observation entries zeroed before the network (e.g. the platoon's clock entry 14)."""
    obs_symlog_scale: float = 0.0
    """Scale of the symlog features of the first observation entries appended (0: none)."""
    obs_symlog_dims: int = 6
    """How many observation entries get symlog features."""
    epochs: int = 6
    """Regression epochs (mean squared error, Adam, warm start) after every round."""
    round0_epoch_factor: int = ROUND0_EPOCH_FACTOR
    """Round 0 fits ``round0_epoch_factor * epochs`` epochs."""
    batch_size: int = 1024
    """Regression minibatch size."""
    weight_decay: float = 0.0
    """Adam weight decay."""
    clip_obs: float = 10.0
    """Observation normaliser clip (mean and variance of round 0's features)."""
    terminal: JsonDict = field(default_factory=dict)
    """Terminal feedback in the learner (``satenv.training.shaping.TerminalFeedback`` fields; ``{}``: off)."""
    learner_shield: Flag = False
    """Fly the learner behind ``satenv.safety.shield`` and also evaluate it shielded each round."""
    baseline_seeds: int = 0
    """How many of the test seeds (the first) the reference and baselines run on (0: all)."""
    final_eval: Flag = True
    """After the last round, write ``final/`` with ``eval.json`` on ``test_seeds``."""

    def __post_init__(self) -> None:
        super().__post_init__()
        check_run_fields(self, ("expert_options", "terminal"))
        for name in ("round0_episodes", "episodes_per_round", "epochs", "round0_epoch_factor", "batch_size"):
            check_int(name, getattr(self, name), minimum=1)
        for name in ("rounds", "train_seed", "baseline_seeds", "obs_symlog_dims"):
            check_int(name, getattr(self, name), minimum=0)
        for name in ("beta", "noise_share", "paper_start_share"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 1:
                raise ValueError(f"{name} must be a number in [0, 1], got {v!r}")
        for name in ("noise_std", "weight_decay", "obs_symlog_scale"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v < math.inf:
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        check_number("clip_obs", self.clip_obs, 0.0, math.inf)
        for name in ("squash", "learner_shield", "collect_through_collisions", "final_eval"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be a bool, got {getattr(self, name)!r}")
        from satenv.training.actor import ACTIVATIONS
        from satenv.training.shaping import ObsFeatures

        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {sorted(ACTIVATIONS)}, got {self.activation!r}")
        object.__setattr__(self, "obs_drop_dims", tuple(self.obs_drop_dims))
        ObsFeatures(self.obs_symlog_scale, self.obs_symlog_dims, self.obs_drop_dims)
        self._resolve_expert()
        self._check_seed_splits()

    def _resolve_expert(self) -> None:
        from satenv.baselines.experts import EXPERTS
        from satenv.baselines.registry import BASELINES

        name = self.expert
        if name is None:
            system = self.system
            if system is None:
                raise ValueError(f"expert: env {self.env_id!r} is not a task of a satenv.tasks system; name the "
                                 f"expert (--expert, one of {sorted(EXPERTS)} or of satenv.baselines.BASELINES)")
            name = tasks.system(system).expert
        if not isinstance(name, str) or (name not in EXPERTS and name not in BASELINES):
            raise ValueError(f"expert must be one of {sorted(EXPERTS)} or a name of satenv.baselines.BASELINES "
                             f"{sorted(BASELINES)}, got {name!r}")
        object.__setattr__(self, "expert", name)

    def _check_seed_splits(self) -> None:
        """With a task: the training episodes on train seeds, ``eval_seeds`` on validation seeds and
        ``test_seeds`` on test seeds (``satenv.tasks.SEED_SPLITS``)."""
        if self.task is None:
            return
        task = tasks.get(self.task)
        for name, seeds, split in (("train_seed", (self.train_seed,), "train"),
                                   ("eval_seeds", self.eval_seeds, "validation"),
                                   ("test_seeds", self.test_seeds, "test")):
            wrong = [s for s in seeds if task.split_of(s) != split]
            if wrong:
                raise ValueError(f"{name} must be {split} seeds of task {task.name} (satenv.tasks.SEED_SPLITS: "
                                 f"{_band(split)}), got {wrong[:3]}{'...' if len(wrong) > 3 else ''}")

    @property
    def system(self) -> str | None:
        """The :data:`satenv.tasks.SYSTEMS` name of the task's system (``None`` without one)."""
        return None if self.task is None else (tasks.get(self.task).system or None)


ImitationConfig = DaggerConfig
"""The name of earlier releases (one config, one engine)."""


def _band(split: str) -> str:
    seeds = tasks.SEED_SPLITS[split]
    return f"{seeds[0]}-{seeds[-1]}"


def system_config(system: str, **overrides: Any) -> DaggerConfig:
    """The config of a run on ``system``'s training task with :data:`SYSTEM_DEFAULTS` (an old
    system name maps, :data:`satenv.training.recipes.LEGACY_SYSTEM_NAMES`), ``overrides`` on top."""
    from satenv.training.recipes import system_name

    name = system_name(system)
    return DaggerConfig(**{"task": tasks.training_task(name).name, **SYSTEM_DEFAULTS.get(name, {}), **overrides})


# --------------------------------------------------------------------------- pieces
class Envs(NamedTuple):
    """The run's envs: collection (training task, collisions may not end it), the paper start's
    collection env (``None`` without a paper task), and their evaluation twins."""

    collect: Any
    paper: Any
    eval: Any
    paper_eval: Any


def paper_task(cfg: DaggerConfig) -> Any:
    """The paper task of the run's system (``None`` without a system, or when it is the task run)."""
    if cfg.system is None:
        return None
    paper = tasks.paper_task(cfg.system)
    return None if paper.name == cfg.task else paper


def collect_kwargs(cfg: DaggerConfig, kwargs: dict[str, Any]) -> dict[str, Any]:
    """A collection env's kwargs: ``kwargs``, and no end at a collision when asked (satenv envs)."""
    import satenv

    through = cfg.collect_through_collisions and cfg.env_id in satenv.ENV_IDS
    return {**kwargs, "terminate_on_collision": False} if through else dict(kwargs)


def make_envs(cfg: DaggerConfig) -> Envs:
    """:class:`Envs` of ``cfg`` (the paper envs get the run's own ``env_kwargs`` overrides)."""
    from satenv.training.envs import make_env

    collect = make_env(cfg.env_id, **collect_kwargs(cfg, cfg.env_kwargs))
    ev = make_env(cfg.env_id, **cfg.resolved_eval_env_kwargs)
    paper = paper_task(cfg)
    if paper is None:
        return Envs(collect, None, ev, None)
    own = dict(tasks.get(cfg.task).env_kwargs)
    extra = {k: v for k, v in cfg.env_kwargs.items() if k not in own or own[k] != v}
    kwargs = {**paper.env_kwargs, **extra}
    return Envs(collect, make_env(paper.env_id, **collect_kwargs(cfg, kwargs)), ev,
                make_env(paper.env_id, **{**kwargs, **cfg.eval_env_kwargs}))


def make_expert(name: str, env: Any, options: dict[str, Any]) -> Any:
    """The expert ``name`` for ``env`` (``satenv.baselines.experts.make``)."""
    from satenv.baselines.experts import make

    return make(name, env, **options)


def features(cfg: DaggerConfig) -> Any:
    """The observation features of the network (:class:`satenv.training.shaping.ObsFeatures`)."""
    from satenv.training.shaping import ObsFeatures

    return ObsFeatures(cfg.obs_symlog_scale, cfg.obs_symlog_dims, tuple(cfg.obs_drop_dims))


def collect_episode(env: Any, expert: Any, learner: Any, seed: int, beta: float, noise: float,
                    rng: np.random.Generator) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """One episode: every visited observation with the expert's label, the env state, agent and
    step (``rows``); and how the flown episode ended (``stats``: steps, final position error,
    collision, closest approach). The expert's action is flown with probability ``beta`` per step
    (always without a ``learner``), the learner's otherwise, plus Gaussian noise of std ``noise``."""
    obs, _ = env.reset(seed=seed)
    expert.reset(seed=seed)
    if learner is not None:
        learner.reset(seed=seed)
    order = list(env.possible_agents)
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
            rows["agent"].append(order.index(a))
            rows["t"].append(t)
        flown = labels if learner is None or rng.random() < beta else learner.act(obs)
        if noise > 0:
            flown = {a: np.clip(v + rng.normal(0, noise, np.shape(v)), -1, 1).astype(np.float32)
                     for a, v in flown.items()}
        obs, _, _, _, infos = env.step(flown)
        collided |= any(bool(i.get("collision", False)) for i in infos.values())
        min_sep = min(min_sep, *(float(i.get("min_separation", np.inf)) for i in infos.values()))
        t += 1
    errors = [float(np.linalg.norm(np.asarray(i["tracking_error"])[:3])) for i in infos.values()
              if "tracking_error" in i]
    stats = {"seed": seed, "steps": t, "final_error_m": round(max(errors), 4) if errors else None,
             "collision": collided, "min_separation_m": round(min_sep, 3) if math.isfinite(min_sep) else None,
             "learner": learner is not None, "noise": noise}
    return {k: np.asarray(v, dtype=np.float32 if k in ("obs", "act") else None) for k, v in rows.items()}, stats


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


def fit(actor: Any, normalizer: Any, feats: Any, x: np.ndarray, y: np.ndarray, cfg: DaggerConfig, generator: Any,
        epochs: int) -> float:
    """:func:`regress` of ``actor`` on the normalised features of ``x``."""
    return regress(actor, normalizer(feats(x.astype(np.float64))), y, lr=cfg.lr, epochs=epochs,
                   batch_size=cfg.batch_size, generator=generator, weight_decay=cfg.weight_decay)


def evaluate(env: Any, policy: Any, seeds: Any) -> dict[str, Any]:
    """:func:`satenv.scoring.aggregate` of the episodes on ``seeds``."""
    return scoring.aggregate(scoring.run_episodes(env, policy, seeds))


def label_path(run: Path, k: int) -> Path:
    """Where round ``k``'s labels are saved."""
    return run / "labels" / f"round_{k:04d}.npz"


def round_folder(run: Path, k: int) -> Path:
    """Round ``k``'s policy folder."""
    return run / "rounds" / f"{k:04d}"


def load_labels(run: Path, rounds: int) -> tuple[np.ndarray, np.ndarray]:
    """The observations and clipped expert actions of rounds ``0 .. rounds - 1`` (the rounds
    ``history.json`` records as complete; a label file of a later, unfinished round is ignored)."""
    from satenv.training.runfolder import RunFolderError

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


def with_prior_labels(cfg: DaggerConfig, obs_dim: int, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``cfg.prior_labels`` (read with ``allow_pickle=False``) before the run's own labels ``x, y``."""
    xs, ys = [], []
    for name in cfg.prior_labels:
        try:
            with np.load(name, allow_pickle=False) as d:
                xs.append(d["obs"])
                ys.append(np.clip(d["act"], -1, 1))
        except (OSError, KeyError, ValueError) as err:
            raise ValueError(f"prior_labels {name!r}: cannot be read ({type(err).__name__}: {str(err)[:80]})") from None
        if xs[-1].ndim != 2 or xs[-1].shape[1] != obs_dim or len(ys[-1]) != len(xs[-1]):
            raise ValueError(f"prior_labels {name!r}: observations {xs[-1].shape} do not fit this env's {obs_dim} "
                             f"entries (or the actions do not match them)")
    if not xs:
        return x, y
    if len(x):
        xs.append(x)
        ys.append(y)
    return np.concatenate(xs), np.concatenate(ys)


def read_history(run: Path) -> list[dict[str, Any]]:
    """The complete rounds of a run (``history.json``, written last in each round: the run's record
    of progress); ``[]`` for a new run. A malformed file is a :class:`satenv.training.runfolder.RunFolderError`."""
    from satenv.training.runfolder import RunFolderError, read_json

    path = run / "history.json"
    if not path.exists():
        return []
    history = read_json(path, "a list of finished DAgger rounds")
    if not isinstance(history, list) or any(not isinstance(h, dict) or h.get("round") != k
                                            for k, h in enumerate(history)):
        raise RunFolderError(f"{path}: expected a list of rounds 0, 1, ... (objects with 'round'), got "
                             f"{str(history)[:80]}")
    return history


def plot_curve(history: list[dict[str, Any]], path: Path) -> None:
    """Validation success and collision episodes (network alone, and shielded when recorded) and
    the regression error against the number of labels."""
    from satenv.render import new_figure  # own canvas: the caller's backend is left alone

    try:
        fig = new_figure((13, 3.6), 90, layout="constrained")
    except ImportError:  # plotting is optional
        return
    labels = [h["labels"] for h in history]
    ax = fig.subplots(1, 3)
    ax[0].plot(labels, [h["val"]["success_rate"] for h in history], "o-", label="random starts")
    if all("paper" in h for h in history):
        ax[0].plot(labels, [h["paper"]["success_rate"] for h in history], "s--", label="paper start")
    sh = [(h["labels"], h["shield"]["val"]) for h in history if "shield" in h]
    if sh:
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
    last = history[-1]
    fig.suptitle(f"DAgger, {last.get('system') or last.get('task') or ''} (validation seeds)")
    fig.savefig(path, dpi=90)


def reference_name(cfg: DaggerConfig) -> str:
    """The scripted controller ``eval.json``'s ratios are taken against: the expert when it is a
    baseline, else the paper controller of the env (``satenv.tasks.CONTROLLERS``)."""
    from satenv.baselines.registry import BASELINES

    return cfg.expert if cfg.expert in BASELINES else tasks.CONTROLLERS.get(cfg.env_id, "zero")


# --------------------------------------------------------------------------- run
def run(cfg: DaggerConfig, run_dir: str | Path | None = None, *, resume: bool = True) -> Path | None:
    """Run (or, with ``resume``, continue after the last round ``history.json`` records) DAgger in
    ``run_dir`` (default: ``cfg.out_dir``); returns ``final/`` (``None`` when ``final_eval`` is off
    or no round ran)."""
    import torch

    from satenv.safety import shield
    from satenv.training import runfolder
    from satenv.training.actor import MLPActor
    from satenv.training.envs import policy_env_meta
    from satenv.training.policy import (
        LearnedPolicy,
        ObsNormalizer,
        load,
        save_artifacts,
        terminal_from_config,
    )

    run_dir = Path(cfg.out_dir if run_dir is None else run_dir)
    history = read_history(run_dir)          # resume after the last round it records, never by counting files
    if (run_dir / "eval_history.json").is_file() and not history:
        raise ValueError(f"{run_dir} is a run folder of an earlier satenv.training.imitate (eval_history.json, data.npz), "
                         f"which this one cannot continue; replay it in a new folder: --config "
                         f"{run_dir / 'config.json'} --out-dir NEW_DIR")
    if history and not resume:
        raise ValueError(f"{run_dir} already has {len(history)} rounds; pass --resume to continue or choose "
                         "another --out-dir")
    torch.set_num_threads(cfg.torch_threads)
    (run_dir / "labels").mkdir(parents=True, exist_ok=True)
    runfolder.write_json(run_dir / "config.json", {**cfg.to_json(), "out_dir": str(run_dir)}, indent=2)
    envs = make_envs(cfg)
    experts = {id(e): make_expert(cfg.expert, e, cfg.expert_options) for e in (envs.collect, envs.paper) if e is not None}
    feats = features(cfg)
    term = terminal_from_config(cfg.to_json())      # part of the learner, as at inference
    agent = envs.collect.possible_agents[0]
    obs_dim = envs.collect.observation_space(agent).shape[0]
    act_dim = envs.collect.action_space(agent).shape[0]
    meta = policy_env_meta(cfg.env_id, envs.collect, collect_kwargs(cfg, cfg.env_kwargs), cfg.resolved_eval_env_kwargs)
    policy_cfg = {**cfg.to_json(), "out_dir": str(run_dir), "recipe": "satenv.training.imitate"}
    done = len(history)
    x, y = with_prior_labels(cfg, obs_dim, *load_labels(run_dir, done))
    torch.manual_seed(cfg.seed)              # the initial weights: the same in every session
    if cfg.architecture == "set":
        from satenv.training.set_policy import SetActor, slot_layout

        own, slot, k = slot_layout(envs.collect)
        if feats.drop_dims and feats.drop_dims[-1] >= own:
            raise ValueError(f"obs_drop_dims {list(feats.drop_dims)} must be own entries (< {own}) with "
                             "architecture='set' (a dropped slot entry would break the permutation invariance)")
        actor = SetActor(feats.out_dim(obs_dim), act_dim, own, slot, k, list(cfg.set_encoder),
                         list(cfg.net_arch), cfg.activation, cfg.squash)
    else:
        actor = MLPActor(feats.out_dim(obs_dim), act_dim, list(cfg.net_arch), cfg.activation, cfg.squash)
    normalizer = None
    if history:
        runfolder.recover_folder(round_folder(run_dir, done - 1))   # a swap a kill interrupted
        last = load(round_folder(run_dir, done - 1))
        actor.load_state_dict(last.actor.state_dict())
        normalizer = last.normalizer
    paper = paper_task(cfg)
    paper_seeds = paper.seeds("validation", 1) if paper is not None else ()
    t_start = time.perf_counter()
    # the next episode's seed offset: as recorded (the episode counts may have changed between sessions)
    episode = int(history[-1].get("episodes", 0)) if history else 0
    for k in range(done, cfg.rounds):
        # every round's randomness from (seed, round): a resumed run flies exactly the rounds of an
        # uninterrupted one
        generator = torch.Generator().manual_seed(cfg.seed + k)
        rng = np.random.default_rng([cfg.seed, k])
        net = None if k == 0 else LearnedPolicy(actor, normalizer, obs_shape=(obs_dim,), features=feats,
                                                terminal=term)
        learners = {id(e): (shield(net, e) if cfg.learner_shield and net is not None else net)
                    for e in (envs.collect, envs.paper) if e is not None}
        n_eps = cfg.round0_episodes if k == 0 else cfg.episodes_per_round
        parts, flown = [], []
        t0 = time.perf_counter()
        for _ in range(n_eps):
            from_paper = envs.paper is not None and rng.random() < cfg.paper_start_share
            env = envs.paper if from_paper else envs.collect
            noise = cfg.noise_std if (k == 0 and rng.random() < cfg.noise_share) else 0.0
            part, stats = collect_episode(env, experts[id(env)], learners[id(env)], cfg.train_seed + episode,
                                          cfg.beta ** k, noise, rng)
            parts.append(part)
            flown.append({**stats, "paper_start": from_paper})
            if cfg.progress:
                print(f"  episode {json.dumps(flown[-1])} at {time.perf_counter() - t0:.0f}s", flush=True)
            episode += 1
        batch = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
        runfolder.save_with(label_path(run_dir, k), lambda tmp: _savez(tmp, batch))  # noqa: B023 - called at once
        collect_s = time.perf_counter() - t0
        x = batch["obs"] if len(x) == 0 else np.concatenate([x, batch["obs"]])
        y = np.clip(batch["act"], -1, 1) if len(y) == 0 else np.concatenate([y, np.clip(batch["act"], -1, 1)])
        if normalizer is None:
            fx = feats(x.astype(np.float64))
            if cfg.architecture == "set":
                from satenv.training.set_policy import set_statistics

                normalizer = ObsNormalizer(*set_statistics(actor.spec, fx), cfg.clip_obs)
            else:
                normalizer = ObsNormalizer(fx.mean(0), fx.var(0), cfg.clip_obs)
        t1 = time.perf_counter()
        loss = fit(actor, normalizer, feats, x, y, cfg, generator,
                   cfg.epochs * (cfg.round0_epoch_factor if k == 0 else 1))
        fit_s = time.perf_counter() - t1
        policy = LearnedPolicy(actor, normalizer, obs_shape=(obs_dim,), features=feats, meta=meta, terminal=term)
        entry = {"task": cfg.task, "system": cfg.system, "round": k, "labels": int(len(x)), "episodes": episode,
                 "loss": loss, "beta": cfg.beta ** k, "collect_s": round(collect_s, 1), "fit_s": round(fit_s, 1),
                 "val": evaluate(envs.eval, policy, cfg.eval_seeds)}
        if envs.paper_eval is not None:
            entry["paper"] = evaluate(envs.paper_eval, policy, paper_seeds)
        if cfg.learner_shield:
            entry["shield"] = {"val": evaluate(envs.eval, shield(policy, envs.eval), cfg.eval_seeds)}
            if envs.paper_eval is not None:
                entry["shield"]["paper"] = evaluate(envs.paper_eval, shield(policy, envs.paper_eval), paper_seeds)
        history.append({**entry, "session_wall_s": round(time.perf_counter() - t_start, 1), "collected": flown})
        # the round's files, each whole or absent, then history.json: the round is complete
        staged = runfolder.staging(round_folder(run_dir, k))
        save_artifacts(staged, policy, env_meta=meta, config=policy_cfg, source="satenv.training.imitate round checkpoint")
        runfolder.replace_folder(staged, round_folder(run_dir, k))
        runfolder.write_json(run_dir / "history.json", history)
        runfolder.save_with(run_dir / "learning_curve.png", lambda tmp: plot_curve(history, tmp))  # noqa: B023
        _report(k, history[-1], collect_s, fit_s)
    if not cfg.final_eval or not history:
        return None
    policy = LearnedPolicy(actor, normalizer, obs_shape=(obs_dim,), features=feats, meta=meta, terminal=term)
    return finish(cfg, run_dir, policy, {**meta, "rounds": len(history)}, policy_cfg, history, envs.eval)


def finish(cfg: DaggerConfig, run_dir: Path, policy: Any, meta: dict[str, Any], config: dict[str, Any],
           history: list[dict[str, Any]], eval_env: Any) -> Path:
    """``final/``: the last round's network with ``eval.json`` on ``cfg.test_seeds`` beside the
    reference controller (:func:`reference_name`) and ``eval_baselines``, swapped in whole."""
    from satenv.training import runfolder
    from satenv.training.evaluate import cached_baselines, test_summary
    from satenv.training.policy import save_artifacts

    reference = reference_name(cfg)
    names = list(dict.fromkeys([reference, *cfg.eval_baselines]))
    seeds = cfg.test_seeds[:cfg.baseline_seeds] if cfg.baseline_seeds else cfg.test_seeds
    key = {"env_id": cfg.env_id, "eval_env_kwargs": cfg.resolved_eval_env_kwargs}  # baselines at their defaults
    opts = {"progress": cfg.progress, "workers": cfg.workers}
    found = cached_baselines(run_dir / "baselines_test.json", eval_env, names, seeds, key, **opts)
    summary = test_summary(eval_env, policy, found, cfg.test_seeds, reference=reference, **opts,
                           labels=int(history[-1]["labels"]), rounds=len(history), expert=cfg.expert)
    final = run_dir / "final"
    runfolder.recover_folder(final)
    staged = runfolder.staging(final)
    save_artifacts(staged, policy, env_meta=meta, config=config, evaluation=summary,
                   source=f"DAgger of '{cfg.expert}' (satenv.training.imitate, {len(history)} rounds)")
    if (run_dir / "learning_curve.png").is_file():
        (staged / "learning_curve.png").write_bytes((run_dir / "learning_curve.png").read_bytes())
    runfolder.replace_folder(staged, final)
    print(f"final policy after {len(history)} rounds on {len(cfg.test_seeds)} held-out seeds:\n{summary['table']}")
    return final


def _report(k: int, h: dict[str, Any], collect_s: float, fit_s: float) -> None:
    val = h["val"]
    line = (f"round {k}: labels {h['labels']} loss {h['loss']:.4f} val success {val['success_rate']:.2f} "
            f"coll {val['collision_episodes']} fe {val['final_error_m']:.2f}")
    if "paper" in h:
        line += f" paper {h['paper']['success_rate']:.0f}"
    if "shield" in h:
        sv = h["shield"]["val"]
        line += f" | +shield success {sv['success_rate']:.2f} coll {sv['collision_episodes']}"
    print(f"{line} collect {collect_s:.0f}s fit {fit_s:.0f}s", flush=True)


def _savez(path: Path, arrays: dict[str, np.ndarray]) -> None:
    with open(path, "wb") as fh:     # a file object: numpy adds no ".npz" to the temporary name
        np.savez_compressed(fh, **arrays)


# --------------------------------------------------------------------------- CLI
ALIASES = {"--run-dir": "--out-dir", "--val-seeds": "--eval-seeds"}
"""Flags of the earlier recipe CLI -> the flag they mean (``--system S`` means ``--task <S's
training task>``)."""


def upgrade(data: dict[str, Any]) -> dict[str, Any]:
    """A saved ``config.json`` of any release as :class:`DaggerConfig` fields: the recipe's
    (``system``, ``val_seeds``; no env id) and the earlier ``satenv.training.imitate``'s (one episode count
    for every round, no noise, no features, collection in the terminating env, round 0 fitted as
    every round). Unknown keys stay (``config_from_json`` names them)."""
    from satenv.baselines.experts import EXPERTS
    from satenv.training.recipes import LEGACY_SYSTEM_NAMES

    d = {k: v for k, v in data.items() if k not in ("recipe", "shipped_round")}
    if "val_seeds" in d:
        d["eval_seeds"] = d.pop("val_seeds")
    if isinstance(d.get("expert"), str) and ":" in d["expert"]:     # a class path: the registry name, else the system's
        names = {v: k for k, v in EXPERTS.items()}
        d["expert"] = names.get(d["expert"])
        if d["expert"] is None:
            del d["expert"]
    if "system" in d:
        system = d.pop("system")
        d.setdefault("task", tasks.training_task(LEGACY_SYSTEM_NAMES.get(system, system)).name)
    elif "env_id" in d and "round0_episodes" not in d:
        d = {"round0_episodes": d.get("episodes_per_round", 8), "noise_share": 0.0, "paper_start_share": 0.0,
             "collect_through_collisions": False, "round0_epoch_factor": 1, **d}
    return d


def load_saved(path: Path, allow_code_env_id: bool = False) -> DaggerConfig:
    """The :class:`DaggerConfig` of a saved ``config.json`` (:func:`upgrade`), its names vetted
    first (:func:`satenv.training.trust.check_replayed_config`)."""
    from satenv.training.trust import UntrustedDataError, check_replayed_config, read_json

    try:
        data = read_json(path.parent, path.name)
    except UntrustedDataError as err:
        raise UntrustedDataError(f"{path}: {err}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object of config fields, got {type(data).__name__}")
    data = upgrade(data)
    check_replayed_config(data, allow_code_env_id=allow_code_env_id, source=str(path))
    return config_from_json(data, DaggerConfig)


def parse(argv: list[str] | None = None, *, prog: str = "python -m satenv.training.imitate", auto_resume: bool = False,
          defaults: dict[str, str] | None = None) -> tuple[DaggerConfig, bool]:
    """``(config, resume)`` of a command line: the aliases (:data:`ALIASES`, ``--system``) mapped,
    then :func:`satenv.training.config.parse_args` with the flags over a base: ``--config FILE``, else
    (``--resume``, or ``auto_resume`` and a run folder that has one) the run's ``config.json``, else
    the task's :data:`SYSTEM_DEFAULTS` with ``defaults`` (flag -> value, e.g. ``{"--rounds": "1000"}``)
    for the flags not given."""
    from satenv.training.trust import CODE_FLAG

    args = _aliases(list(sys.argv[1:] if argv is None else argv))
    flags = _flag_values(args)
    resume = "--resume" in args
    args = [a for a in args if a != "--resume"]
    config = flags.get("--config")
    if config is not None:
        i = next(i for i, a in enumerate(args) if a == "--config" or a.startswith("--config="))
        del args[i:i + (1 if "=" in args[i] else 2)]
    out = Path(flags.get("--out-dir", DaggerConfig.out_dir))
    allow_code = CODE_FLAG in args
    if config is not None:
        base = load_saved(Path(config), allow_code)
    elif (resume or auto_resume) and (out / "config.json").is_file():
        base = load_saved(out / "config.json", allow_code)
        resume = True
    elif resume:
        raise ValueError(f"--resume: {out / 'config.json'} is missing (a run folder's config.json, written by "
                         "a run without --resume)")
    else:
        base = _fresh_base(flags)
        args = [part for flag, value in (defaults or {}).items() if flag not in flags for part in (flag, value)] + args
    extra = "".join(f" {flag} defaults to {value} here." for flag, value in (defaults or {}).items())
    description = __doc__.split("\n\n")[0] + extra + (
        "\n\n--system S is an alias of --task <S's training task>, --run-dir D of --out-dir D; a task of a "
        "system brings its SYSTEM_DEFAULTS (flags given override them).")
    cfg, _ = parse_args(args, cls=DaggerConfig, base=base, prog=prog, description=description)
    return cfg, resume


def _fresh_base(flags: dict[str, str]) -> DaggerConfig | None:
    """The base of a new run: the task's system defaults (the default task without ``--task`` and
    ``--env-id``); ``None`` (the field defaults, the flags then name the expert) for an env id
    without a task and for a task of no system."""
    from satenv.training.config import DEFAULT_TASK

    task = flags.get("--task")
    if task is None and "--env-id" in flags:
        return None
    name = tasks.get(task or DEFAULT_TASK).name
    if not tasks.get(name).system:
        return None
    return DaggerConfig(**{"task": name, **SYSTEM_DEFAULTS[tasks.get(name).system]})


def _flag_values(args: list[str]) -> dict[str, str]:
    """The last value of each ``--flag VALUE`` / ``--flag=VALUE`` in ``args``."""
    found = {}
    for i, a in enumerate(args):
        if a.startswith("--"):
            name, eq, value = a.partition("=")
            if eq:
                found[name] = value
            elif i + 1 < len(args) and not args[i + 1].startswith("--"):
                found[name] = args[i + 1]
    return found


def _aliases(args: list[str]) -> list[str]:
    """``args`` with :data:`ALIASES` renamed, ``--system S`` as ``--task <training task>`` and a JSON
    list value (the earlier recipe's grammar, e.g. ``--net-arch [16]``) as a comma list."""
    from satenv.training.recipes import system_name

    out: list[str] = []
    it = iter(args)
    for a in it:
        name, eq, value = a.partition("=")
        name = ALIASES.get(name, name)
        if name == "--system":
            value = value if eq else next(it, "")
            out += ["--task", tasks.training_task(system_name(value)).name]
            continue
        out.append(name + eq + value)
    return [_json_list(a) for a in out]


def _json_list(arg: str) -> str:
    if arg.startswith("[") and arg.endswith("]"):
        try:
            value = json.loads(arg)
        except json.JSONDecodeError:
            return arg
        if isinstance(value, list) and all(isinstance(v, (int, float, str)) and not isinstance(v, bool)
                                           for v in value):
            return ",".join(str(v) for v in value)
    return arg


def main(argv: list[str] | None = None, *, prog: str = "python -m satenv.training.imitate", auto_resume: bool = False,
         defaults: dict[str, str] | None = None) -> Path | None:
    """Parse (:func:`parse`) and :func:`run`; returns ``final/`` (``None`` when none is written)."""
    try:
        cfg, resume = parse(argv, prog=prog, auto_resume=auto_resume, defaults=defaults)
    except ValueError as err:
        raise SystemExit(f"error: {err}") from None
    try:
        return run(cfg, resume=resume)
    except ValueError as err:
        raise SystemExit(f"error: {f'cannot resume {cfg.out_dir}: ' if resume else ''}{err}") from None


if __name__ == "__main__":
    warnings.filterwarnings("ignore", category=DeprecationWarning)
    main()
