"""The one imitation config: DAgger and its safe variants as options of one frozen dataclass.

A task of a :data:`satenv.tasks.SYSTEMS` system brings the system's expert and its ``imitation``
hyper-parameters (:func:`system_config`); the seeds come from the task's bands
(``task.seeds(split)``). Saved ``config.json`` files of every earlier release map onto the fields
(:func:`upgrade`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

from satenv import tasks
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
)

__all__ = ["FLIGHTS", "ImitationConfig", "LABELS", "SPACES", "system_config", "upgrade"]

FLIGHTS = ("dagger", "filtered", "alone", "mixed", "handover")
"""Who flies a collection episode. ``"dagger"``: the expert's action with probability ``beta ** k``
per step in round ``k`` (round 0 without a warm start: the expert alone), else the network's. The
safe variants fly the network and record the safety filter at every step: behind the filter
(``"filtered"``), alone (``"alone"``, the filter's output only recorded), alternately
(``"mixed"``: even episodes alone) or alone until the first collision or hard-bound violation,
then behind the filter (``"handover"``)."""
LABELS = ("expert", "filtered", "self", "teacher")
"""What the network imitates: the expert's action as it is, the expert's action through the
filter, the filter's output for the network's own action, or the filter's output for the warm
start's action (the shipped composite, network + filter, as a frozen teacher)."""
SPACES = ("flown", "network")
"""Where the safe loss compares with a label: the flown action (the policy's terminal feedback
blended in) or the network's own output."""
ROUND0_EPOCH_FACTOR = 4
"""A cold network's round 0 fits ``round0_epoch_factor`` times ``epochs``."""
SEQUENCE_FIELDS = ("eval_seeds", "test_seeds", "net_arch", "eval_baselines", "set_encoder", "obs_drop_dims",
                   "prior_labels")
"""The fields that hold a list (a tuple once validated)."""
DEFAULT_TRAIN_SEED = tasks.SEED_SPLITS["train"][600_000]
"""The first training episode's seed (inside the train band)."""


@dataclass(frozen=True)
class ImitationConfig(RunConfig):
    """One imitation run (``satenv imitate``); every field is a ``--flag``."""

    expert: str | None = None
    """The imitated controller: an expert of ``satenv.baselines.experts.EXPERTS`` or a name of
    ``satenv.baselines.BASELINES`` (default: the expert ``satenv.tasks`` names for the system)."""
    expert_options: JsonDict = field(default_factory=dict)
    """Its options, a JSON object."""
    net_arch: Ints = (512, 512, 512)
    """Hidden sizes of the MLP (``architecture="set"``: of the head after the pooling)."""
    architecture: Literal["mlp", "set"] = "mlp"
    """``"mlp"``, or ``"set"`` (a shared encoder of the neighbour slots, pooled, then the head)."""
    set_encoder: Ints = (64, 64)
    """Hidden sizes of the set actor's per-slot encoder."""
    activation: Literal["tanh", "relu", "elu", "silu"] = "relu"
    """The network's activation."""
    squash: Flag = True
    """``tanh`` on the output."""
    lr: float = 5e-4
    """Adam learning rate."""
    weight_decay: float = 0.0
    """Adam weight decay (plain DAgger fit)."""
    epochs: int = 6
    """Epochs of the fit after every round (warm start: the previous round's weights)."""
    round0_epoch_factor: int = ROUND0_EPOCH_FACTOR
    """A cold network's round 0 fits ``round0_epoch_factor * epochs`` epochs."""
    batch_size: int = 1024
    """Minibatch size."""
    out_dir: str = "runs/imitate"
    """Run folder: ``config.json``, ``labels/``, ``rounds/NNNN/``, ``history.json``, ``final/``."""
    rounds: int = 8
    """Rounds (0 builds the envs and the expert only)."""
    round0_episodes: int = 8
    """Episodes of round 0."""
    episodes_per_round: int = 8
    """Episodes of every later round; the run's episode ``i`` resets with ``train_seed + i``."""
    train_seed: int = DEFAULT_TRAIN_SEED
    """Seed of the first training episode (with a task: in its train band)."""
    beta: float = 0.5
    """``fly="dagger"``: the expert's action is flown with probability ``beta ** k`` in round k."""
    noise_share: float = 0.5
    """Share of a cold round 0's episodes flown with Gaussian action noise (DART)."""
    noise_std: float = 0.15
    """Standard deviation of that noise."""
    paper_start_share: float = 0.2
    """Share of episodes flown from the system's paper task."""
    collect_through_collisions: Flag = True
    """A collision does not end a collection episode."""
    obs_drop_dims: Ints = ()
    """Observation entries zeroed before the network."""
    obs_symlog_scale: float = 0.0
    """Scale of the symlog features of the first observation entries (0: none)."""
    obs_symlog_dims: int = 6
    """How many observation entries get symlog features."""
    clip_obs: float = 10.0
    """Observation normaliser clip."""
    terminal: JsonDict = field(default_factory=dict)
    """Terminal feedback in the learner (``satenv.training.shaping.TerminalFeedback`` fields)."""
    prior_labels: Names = ()
    """Label files (``round_NNNN.npz`` with ``obs`` and ``act``) or folders of them, of earlier runs."""
    prior_weight: float = 1.0
    """Weight of the prior labels' term in the safe loss (plain DAgger: fitted as its own labels)."""
    learner_shield: Flag = False
    """Fly the learner behind ``satenv.safety.shield`` (``fly="dagger"``) and score it shielded too."""
    warm_start: str | None = None
    """A policy folder the network starts from; its shipped filter is the run's filter, and with
    ``label="teacher"`` it is the teacher."""
    fly: Literal["dagger", "filtered", "alone", "mixed", "handover"] = "dagger"
    """Who flies the collection episodes (:data:`FLIGHTS`)."""
    label: Literal["expert", "filtered", "self", "teacher"] = "expert"
    """What the network imitates (:data:`LABELS`; all but ``"expert"`` need a safe ``fly``)."""
    w_int: float = 1.0
    """Safe loss: weight of the distance to the filter's output where it intervened."""
    w_bar: float = 10.0
    """Safe loss: weight of the barrier hinge on the filter's constraint rows."""
    bar_margin: float = 0.02
    """Safe loss: the hinge's margin inside the rows."""
    imitation_space: Literal["flown", "network"] = "flown"
    """Safe loss: where the imitation terms compare (:data:`SPACES`)."""
    prior_space: Literal["", "flown", "network"] = ""
    """Safe loss: where the prior term compares (``""``: ``imitation_space``)."""
    label_filter: JsonDict = field(default_factory=dict)
    """``SafetyConfig`` options over the shipped filter, for the labels and barrier rows only."""
    collect_decisions: int = 0
    """A safe collection episode stops after this many decisions (0: at its end)."""
    alone_weight: float = 1.0
    """Safe loss: weight of the rows flown by the network alone."""
    shield_seeds: int = 0
    """How many of ``eval_seeds`` (the first) score the network behind the filter (0: all)."""
    baseline_seeds: int = 0
    """How many of the test seeds the reference and baselines run on in ``final/`` (0: all)."""
    final_eval: Flag = True
    """After the last round, write ``final/`` with ``eval.json`` on ``test_seeds``."""

    def __post_init__(self) -> None:
        for name in SEQUENCE_FIELDS:                 # before the shared checks iterate them
            if not isinstance(getattr(self, name), list | tuple):
                raise ValueError(f"{name} must be a list, got {getattr(self, name)!r:.60}")
        super().__post_init__()
        check_run_fields(self, ("expert_options", "terminal", "label_filter"))
        for name in ("round0_episodes", "episodes_per_round", "epochs", "round0_epoch_factor", "batch_size"):
            check_int(name, getattr(self, name), minimum=1)
        for name in ("rounds", "train_seed", "baseline_seeds", "obs_symlog_dims", "collect_decisions",
                     "shield_seeds"):
            check_int(name, getattr(self, name), minimum=0)
        for name in ("beta", "noise_share", "paper_start_share"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not 0 <= v <= 1:
                raise ValueError(f"{name} must be a number in [0, 1], got {v!r:.60}")
        for name in ("noise_std", "weight_decay", "obs_symlog_scale", "w_int", "w_bar", "bar_margin",
                     "prior_weight", "alone_weight"):
            _finite(name, getattr(self, name))
        check_number("clip_obs", self.clip_obs, 0.0, math.inf)
        for name in ("squash", "learner_shield", "collect_through_collisions", "final_eval"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be a bool, got {getattr(self, name)!r}")
        self._check_choices()
        self._check_safe()
        if not self.set_encoder or any(isinstance(w, bool) or not isinstance(w, int) or w < 1
                                       for w in self.set_encoder):
            raise ValueError("set_encoder must be a non-empty tuple of positive ints (e.g. 64,64), "
                             f"got {self.set_encoder!r:.60}")
        object.__setattr__(self, "set_encoder", tuple(self.set_encoder))
        self._check_baselines()
        object.__setattr__(self, "obs_drop_dims", tuple(self.obs_drop_dims))
        if not isinstance(self.prior_labels, list | tuple) or not all(isinstance(n, str) for n in self.prior_labels):
            raise ValueError(f"prior_labels must be a list of label files or folders, got {self.prior_labels!r:.60}")
        object.__setattr__(self, "prior_labels", tuple(self.prior_labels))
        from satenv.training.shaping import ObsFeatures, TerminalFeedback

        ObsFeatures(self.obs_symlog_scale, self.obs_symlog_dims, self.obs_drop_dims)
        TerminalFeedback.from_config({"terminal": self.terminal})     # its fields checked before a run starts
        self._resolve_expert()
        self._check_seed_splits()

    def _check_choices(self) -> None:
        from satenv.training.actor import ACTIVATIONS

        choices = {"activation": tuple(ACTIVATIONS), "architecture": ("mlp", "set"), "fly": FLIGHTS,
                   "label": LABELS, "imitation_space": SPACES, "prior_space": ("", *SPACES)}
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name} must be one of {list(allowed)}, got {getattr(self, name)!r:.60}")

    def _check_safe(self) -> None:
        if self.label != "expert" and not self.safe:
            raise ValueError(f"label {self.label!r} labels through the safety filter: fly must be one of "
                             f"{list(FLIGHTS[1:])}, got fly={self.fly!r}")
        if self.safe and self.warm_start is None:
            raise ValueError(f"fly={self.fly!r} flies the network from the first round: warm_start must name "
                             "a policy folder")
        if self.warm_start is not None and (not isinstance(self.warm_start, str) or not self.warm_start):
            raise ValueError(f"warm_start must be a policy folder path, got {self.warm_start!r:.60}")
        if self.label_filter:
            from satenv.safety import SafetyConfig

            try:
                SafetyConfig.from_options(**self.label_filter)
            except (TypeError, ValueError) as err:
                raise ValueError(f"label_filter: {err}") from None

    def _check_baselines(self) -> None:
        from satenv.baselines.registry import BASELINES

        wrong = [b for b in self.eval_baselines if b not in BASELINES and b != "auto"]
        if wrong:
            raise ValueError(f"eval_baselines must be names of satenv.baselines.BASELINES {sorted(BASELINES)} or "
                             f"'auto', got {wrong[:3]!r:.80}")

    def _resolve_expert(self) -> None:
        from satenv.baselines.experts import EXPERTS
        from satenv.baselines.registry import BASELINES

        name = self.expert
        if name is None and self.label in ("self", "teacher"):
            return                                          # no expert is flown or asked
        if name is None:
            if self.system is None:
                raise ValueError(f"expert: env {self.env_id!r} is not a task of a satenv.tasks system; name the "
                                 f"expert (--expert, one of {sorted(EXPERTS)} or of satenv.baselines.BASELINES)")
            name = tasks.system(self.system).expert
        if not isinstance(name, str) or (name not in EXPERTS and name not in BASELINES):
            raise ValueError(f"expert must be one of {sorted(EXPERTS)} or a name of satenv.baselines.BASELINES "
                             f"{sorted(BASELINES)}, got {name!r:.60}")
        object.__setattr__(self, "expert", name)

    def _check_seed_splits(self) -> None:
        """With a task: training episodes on train seeds, ``eval_seeds`` on validation seeds and
        ``test_seeds`` on test seeds (the task's bands)."""
        if self.task is None:
            return
        task = tasks.get(self.task)
        for name, seeds, split in (("train_seed", (self.train_seed,), "train"),
                                   ("eval_seeds", self.eval_seeds, "validation"),
                                   ("test_seeds", self.test_seeds, "test")):
            wrong = [s for s in seeds if task.split_of(s) != split]
            if wrong:
                band = tasks.show_seeds((tasks.SEED_SPLITS[split][0], tasks.SEED_SPLITS[split][-1]))
                raise ValueError(f"{name} must be {split} seeds of task {task.name} ({band}), "
                                 f"got {wrong[:3]}{'...' if len(wrong) > 3 else ''}")

    @property
    def system(self) -> str | None:
        """The :data:`satenv.tasks.SYSTEMS` name of the task's system (``None`` without one)."""
        return None if self.task is None else (tasks.get(self.task).system or None)

    @property
    def safe(self) -> bool:
        """Whether the collection records the safety filter (a safe ``fly``) and the safe loss fits."""
        return self.fly != "dagger"


def _finite(name: str, v: Any) -> None:
    if isinstance(v, bool) or not isinstance(v, int | float) or not 0 <= v < math.inf:
        raise ValueError(f"{name} must be a finite number >= 0, got {v!r:.60}")


def system_defaults(system: str) -> dict[str, Any]:
    """The config fields of ``system``'s ``imitation`` entry in :data:`satenv.tasks.SYSTEMS` (the
    count ``validation_seeds`` as the first seeds of its training task's validation band)."""
    entry = dict(tasks.system(system).imitation)
    n = entry.pop("validation_seeds", None)
    if n is not None:
        entry["eval_seeds"] = tasks.training_task(system).seeds("validation", n)
    return {k: dict(v) if hasattr(v, "keys") else v for k, v in entry.items()}


def system_config(system: str, **overrides: Any) -> ImitationConfig:
    """A run on ``system``'s training task with its hyper-parameters, ``overrides`` on top (an old
    system name maps, :data:`satenv.training.recipes.LEGACY_SYSTEM_NAMES`)."""
    from satenv.training.recipes import system_name

    name = system_name(system)
    return ImitationConfig(**{"task": tasks.training_task(name).name, **system_defaults(name), **overrides})


SAFE_RENAMED = {"learning_rate": "lr", "val_shield_seeds": "shield_seeds"}
"""Fields of the earlier safe-variant config -> this config's."""


def upgrade(data: dict[str, Any]) -> dict[str, Any]:
    """A saved ``config.json`` of any release as :class:`ImitationConfig` fields. DAgger's: the
    recipe's (``system``, ``val_seeds``) and the earliest engine's (one episode count, no noise, no
    features, round 0 fitted as every round). The safe variant's (a ``safe_dagger`` object, or its
    flat fields): ``system`` -> the training task, ``val_seeds`` (a count) -> the first validation
    seeds, ``learning_rate`` -> ``lr``, its defaults ``fly="filtered"`` and ``label="filtered"``.
    Unknown keys stay (:func:`satenv.training.config.config_from_json` names them)."""
    if isinstance(data.get("safe_dagger"), dict):
        return _upgrade_safe(data["safe_dagger"])
    if "warm_start" in data and "system" in data and "w_bar" in data:       # the earlier safe config, flat
        return _upgrade_safe(data)
    return _upgrade_dagger(data)


def _upgrade_safe(data: dict[str, Any]) -> dict[str, Any]:
    d = {SAFE_RENAMED.get(k, k): v for k, v in data.items() if k not in ("recipe", "round")}
    system = _system(d.pop("system", "platoon-pereira2022"))
    task = tasks.training_task(system)
    d["task"] = task.name
    d.setdefault("fly", "filtered")
    d.setdefault("label", "filtered")
    d.setdefault("paper_start_share", 0.0)       # the earlier safe variant flew the training task only
    d.setdefault("final_eval", False)            # and shipped a round chosen on validation
    d.setdefault("round0_episodes", d.get("episodes_per_round", 12))    # every round flew as many
    n = d.pop("val_seeds", 100)
    d["eval_seeds"] = list(task.seeds("validation", n)) if isinstance(n, int) and not isinstance(n, bool) else n
    prior = _moved(d.get("prior_labels", ""))
    d["prior_labels"] = [prior] if isinstance(prior, str) and prior else ([] if prior == "" else prior)
    d["warm_start"] = _moved(d.get("warm_start"))
    d.setdefault("expert_options", dict(tasks.system(system).imitation.get("expert_options", {})))
    return d


MOVED = {"training/policies/": "satenv/training/policies/", "training/runs/": "studies/runs/"}
"""Folders of the earlier layout -> where they live now (the shipped policies are package data,
the run folders are studies)."""


def _moved(path: Any) -> Any:
    """A saved path of the earlier layout (:data:`MOVED`) as it is now."""
    if isinstance(path, str):
        for old, new in MOVED.items():
            if path.startswith(old):
                return new + path[len(old):]
    return path


def _upgrade_dagger(data: dict[str, Any]) -> dict[str, Any]:
    from satenv.baselines.experts import EXPERTS

    d = {k: v for k, v in data.items() if k not in ("recipe", "shipped_round")}
    if "val_seeds" in d:
        d["eval_seeds"] = d.pop("val_seeds")
    if isinstance(d.get("expert"), str) and ":" in d["expert"]:     # a class path: the registry's name
        names = {v: k for k, v in EXPERTS.items()}
        d["expert"] = names.get(d["expert"])
        if d["expert"] is None:
            del d["expert"]
    if "system" in d:
        d.setdefault("task", tasks.training_task(_system(d.pop("system"))).name)
    elif "env_id" in d and "round0_episodes" not in d:
        d = {"round0_episodes": d.get("episodes_per_round", 8), "noise_share": 0.0, "paper_start_share": 0.0,
             "collect_through_collisions": False, "round0_epoch_factor": 1, **d}
    return d


def _system(name: Any) -> str:
    from satenv.training.recipes import LEGACY_SYSTEM_NAMES

    if not isinstance(name, str):
        raise ValueError(f"system must be a name of satenv.tasks.SYSTEMS, got {name!r:.60}")
    return tasks.system(LEGACY_SYSTEM_NAMES.get(name, name)).name


def from_json(data: dict[str, Any]) -> ImitationConfig:
    """:class:`ImitationConfig` of a saved ``config.json`` object of any release (:func:`upgrade`)."""
    return config_from_json(upgrade(data), ImitationConfig)
