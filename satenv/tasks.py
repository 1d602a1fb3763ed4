"""The task registry: what is run and how it is scored, one home for training and benchmarks.

A :class:`Task` is a named env configuration with everything a fair comparison needs: the env id
and keyword arguments, the paper system it belongs to, that system's controller (the comparator)
and expert (for imitation) by registry name, the seeds of each split and the perturbations it is
evaluated under::

    from satenv import tasks
    task = tasks.get("cluster-case1-random")
    env = task.make_env()                       # satenv.make(task.env_id, **task.env_kwargs)
    test = task.seeds("test")                   # the held-out seeds every published number uses
    tasks.training_task("cluster-li2022").name  # 'cluster-case1-random' (a system's training task)

Seed splits (:data:`SEED_SPLITS`) are the same bands for every task and disjoint by construction
(:func:`check_splits` runs at import): train seeds for training runs, validation seeds for every
choice (round, checkpoint, hyper-parameter), test seeds only for the reported result. A
deterministic task (the paper's own start) has a single test seed: every seed gives the same
episode, so nobody reports an interval on it.

Each paper system (:data:`SYSTEMS`) has a **training task** (a randomised start drawn from the
seed, usable by RL: every start outside the keep-out zones) and a **paper task** (the paper's start,
deterministic, reproducing the paper). The other tasks (``role="extra"``) are variants the
scoreboard also runs (other topologies, J2 truth, swarms).

A training task and its ladder's rungs build their env with ``reward="training"`` (in their
``env_kwargs``, so ``satenv.make_vec(task.env_id, n, **task.env_kwargs)`` trains on it too): the
reward of :mod:`satenv.rewards`, which points at success. Every other task, and a bare
``satenv.make``, keeps the paper's cost; ``task.paper_env_kwargs`` (what the scoreboard builds)
gives any task's env with the paper's cost.

Each system has a **ladder** (:func:`ladder`, :data:`LADDERS`): registered tasks, easiest first,
ending at its training task. A rung changes only what makes the task hard (where the starts are
drawn, the number of agents, the success tolerance, the horizon, the decision period), never the
physics; ``docs/tasks.md`` tabulates them.

The registry imports no baseline: controllers and experts are names of the one controller registry,
``satenv.baselines.registry`` (``make`` and ``make_expert`` resolve them; a test checks every one does).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from satenv.errors import SatenvError, SatenvTypeError

__all__ = ["CONTROLLERS", "LADDERS", "SEED_SPLITS", "SPLITS", "SYSTEMS", "TASKS", "MAX_SEEDS", "System", "Task",
           "check_splits", "get", "ladder", "names", "paper_task", "parse_seeds", "show_seeds", "system",
           "training_task"]

SPLITS = ("train", "validation", "test")
"""The seed splits, in the order a study uses them."""

SEED_SPLITS: Mapping[str, range] = MappingProxyType({
    "train": range(0, 700_000),
    "validation": range(700_000, 800_000),
    "test": range(900_000, 901_000),
})
"""The seed band of each split, the same for every task: training runs draw from ``train``,
every choice is made on ``validation``, published numbers use ``test`` only (1,000 seeds)."""

MAX_SEEDS = 100_000
"""The most seeds one seed list may name (a typo such as ``0-10000000`` is an error, not hours of
evaluation)."""


def check_splits(splits: Mapping[str, range] = SEED_SPLITS) -> None:
    """Raise :class:`SatenvError` unless the splits are non-empty, non-negative and pairwise
    disjoint (run at import on :data:`SEED_SPLITS`)."""
    bands = sorted((r.start, r.stop, name) for name, r in splits.items())
    for start, stop, name in bands:
        if start < 0 or stop <= start:
            raise SatenvError(f"seed split {name!r} must be a non-empty band of seeds >= 0, got "
                              f"{start}..{stop - 1}")
    for (_, stop, a), (start, _, b) in zip(bands, bands[1:]):   # noqa: B905 (consecutive pairs)
        if start < stop:
            raise SatenvError(f"seed splits {a!r} and {b!r} overlap (seeds {start}..{stop - 1})")


check_splits()


def parse_seeds(text: str | Iterable[str]) -> tuple[int, ...]:
    """``"0-9"`` (inclusive), ``"0,3,7"``, ``"0-4,10"`` or several such strings -> the seeds in
    the order given, duplicates dropped; at least one, at most :data:`MAX_SEEDS`. ``"a:b"``
    (Python's half-open range) is accepted too. The one seed grammar of every command line."""
    if not isinstance(text, str) and not (isinstance(text, Iterable) and all(isinstance(t, str) for t in text)):
        raise SatenvTypeError(f"seeds must be a string like '0-9' or '0,3,7' (or a list of them), got "
                              f"{type(text).__name__}")
    parts = [p.strip() for t in ([text] if isinstance(text, str) else text) for p in t.split(",")]
    seeds: dict[int, None] = {}
    try:
        for part in filter(None, parts):
            sep = ":" if ":" in part else ("-" if "-" in part[1:] else None)
            if sep is None:
                lo, hi = int(part), int(part) + 1
            else:
                a, b = part.split(sep, 1)
                lo, hi = int(a), int(b) + (sep == "-")
            if lo < 0 or hi <= lo:
                raise ValueError
            if len(seeds) + hi - lo > MAX_SEEDS:
                raise OverflowError
            seeds.update(dict.fromkeys(range(lo, hi)))
        if not seeds:
            raise ValueError
    except OverflowError:
        raise SatenvError(f"seeds: {text!r:.80} names more than {MAX_SEEDS} seeds") from None
    except ValueError:
        raise SatenvError(f"seeds must be non-negative integers or ranges like '0-9' (inclusive) or "
                          f"'0,3,7', got {text!r:.80}") from None
    return tuple(seeds)


def show_seeds(seeds: Iterable[int]) -> str:
    """``A-B`` for a run of consecutive seeds (the :func:`parse_seeds` range syntax), else
    comma-separated."""
    seeds = tuple(seeds)
    if len(seeds) > 2 and list(seeds) == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"{seeds[0]}-{seeds[-1]}"
    return ",".join(map(str, seeds))


CONTROLLERS: Mapping[str, str] = MappingProxyType({
    "platoon_v0": "dmpc", "cluster_v0": "tube_rdmpc", "servicing_v0": "nmpc", "formation_v0": "cgmres"})
"""The controller each env's paper proposes (a ``baselines`` registry name): the comparator of every
task on that env, the reference of the board's normalised score."""


@dataclass(frozen=True)
class System:
    """A paper system: its label, its expert for imitation (a ``satenv.baselines.registry`` expert name)
    and its training and paper tasks; its controller is its env's (:data:`CONTROLLERS`)."""

    name: str
    label: str
    expert: str
    training_task: str
    paper_task: str
    imitation: Mapping[str, Any] = field(default_factory=dict)
    """Imitation hyper-parameters of the system (``satenv.training.imitation`` config fields;
    ``validation_seeds``: how many of the validation band each round is scored on)."""

    @property
    def controller(self) -> str:
        return CONTROLLERS[TASKS[self.training_task].env_id]


_SHORT_EPISODES = {"round0_episodes": 40, "episodes_per_round": 16, "noise_std": 0.15, "obs_symlog_scale": 20.0,
                   "epochs": 6, "validation_seeds": 3}
# the reference controllers of the cluster and servicing (tube-RDMPC, NMPC) take minutes an episode:
# imitation scores them on the first test seeds only (baseline_seeds), the network on all; the
# cooperative NMPC warm-starts against the other spacecraft's previous plan and C/GMRES and the
# pereira2023 DMPC continue their previous solutions, so their labels are close to, not exactly,
# what they would do
SYSTEMS: Mapping[str, System] = MappingProxyType({s.name: s for s in [
    System("platoon-pereira2023", "platoon, pereira2023", "dmpc",
           "platoon-tplf30-random-cw", "platoon-PLF-cw", MappingProxyType({**_SHORT_EPISODES, "obs_drop_dims": (14,)})),
    System("platoon-pereira2022", "platoon, pereira2022 §5.1", "joint_platoon_mpc",
           "platoon-pereira2022-random", "platoon-pereira2022",
           MappingProxyType({**_SHORT_EPISODES, "validation_seeds": 12, "obs_drop_dims": (14,),
                             "expert_options": MappingProxyType({"coupling": "sequential"})})),
    System("cluster-li2022", "cluster, li2022", "replanning_tube_rdmpc",
           "cluster-case1-random", "cluster-case1",
           MappingProxyType({"round0_episodes": 6, "episodes_per_round": 4, "validation_seeds": 3,
                             "obs_drop_dims": (18,), "obs_symlog_scale": 300.0, "noise_std": 0.1, "epochs": 20,
                             "baseline_seeds": 3})),
    System("servicing-pereira2022", "servicing, pereira2022 §5.2", "nmpc",
           "servicing-pereira2022-random", "servicing-pereira2022",
           MappingProxyType({"round0_episodes": 4, "episodes_per_round": 2, "validation_seeds": 3,
                             "obs_drop_dims": (), "obs_symlog_scale": 10.0, "noise_std": 0.05, "epochs": 20,
                             "baseline_seeds": 3})),
    System("formation-kannan2022-position", "formation, kannan2022 position", "cgmres",
           "formation-kannan2022-position-random", "formation-kannan2022-position", MappingProxyType(_SHORT_EPISODES)),
    System("formation-kannan2022-collision", "formation, kannan2022 collision", "cgmres",
           "formation-kannan2022-collision-random", "formation-kannan2022-collision",
           MappingProxyType(_SHORT_EPISODES)),
]})
"""The six paper systems, in the order the board's summary lists them."""


def _frozen(kwargs: Mapping[str, Any]) -> Mapping[str, Any]:
    return MappingProxyType(dict(kwargs))


@dataclass(frozen=True)
class Task:
    """One named task (frozen): ``make_env()`` builds its env, ``seeds(split)`` gives its seeds.

    ``cost_budget`` is the per-episode safety-cost budget the paper implies (the env's ``cost``
    info summed over an episode): ``0.0`` where collisions and keep-out zones are hard constraints,
    ``None`` where the paper sets no safety constraint (its target formation itself is in contact).
    Constrained-RL libraries read it from here or from ``env.metadata["cost_budget"]``.
    """

    name: str
    env_id: str
    env_kwargs: Mapping[str, Any] = field(default_factory=dict)
    system: str | None = None
    role: str = "extra"
    description: str = ""
    perturbations: tuple[str, ...] = ()
    cost_budget: float | None = 0.0

    def __post_init__(self) -> None:
        from satenv import ENV_IDS

        if not isinstance(self.name, str) or not self.name:
            raise SatenvError(f"task name must be a non-empty string, got {self.name!r}")
        if self.env_id not in ENV_IDS:
            raise SatenvError(f"task {self.name}: env_id must be one of {list(ENV_IDS)}, got {self.env_id!r}")
        if self.role not in ("training", "paper", "extra"):
            raise SatenvError(f"task {self.name}: role must be 'training', 'paper' or 'extra', got {self.role!r}")
        object.__setattr__(self, "env_kwargs", _frozen(self.env_kwargs))

    @property
    def randomized(self) -> bool:
        """Whether the start is drawn from the seed (else every seed gives the same episode)."""
        return bool(self.env_kwargs.get("randomize", False))

    @property
    def controller(self) -> str:
        """The controller of the task's env (:data:`CONTROLLERS`): the comparator of its results."""
        return CONTROLLERS[self.env_id]

    @property
    def expert(self) -> str | None:
        """The system's expert for imitation (a ``satenv.baselines.registry`` expert name)."""
        return SYSTEMS[self.system].expert if self.system else None

    def seeds(self, split: str, n: int | None = None) -> tuple[int, ...]:
        """The first ``n`` seeds (all when ``None``) of ``split`` (``"train"``, ``"validation"``,
        ``"test"``); a deterministic task has one test seed."""
        if split not in SEED_SPLITS:
            raise SatenvError(f"split must be one of {list(SPLITS)}, got {split!r:.40}")
        band = SEED_SPLITS[split]
        if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
            raise SatenvError(f"n must be a positive int or None, got {n!r:.40}")
        if split == "test" and not self.randomized:
            return (band.start,)
        return tuple(band[: len(band) if n is None else min(n, len(band))])

    def split_of(self, seed: int) -> str | None:
        """The split a seed belongs to (``None`` for a seed in no band)."""
        return next((s for s, band in SEED_SPLITS.items() if seed in band), None)

    @property
    def paper_env_kwargs(self) -> Mapping[str, Any]:
        """``env_kwargs`` without the ``reward`` keyword: the env with the paper's cost (the
        scoreboard's and the reproductions' env)."""
        return _frozen({k: v for k, v in self.env_kwargs.items() if k != "reward"})

    def make_env(self, **overrides: Any) -> Any:
        """``satenv.make(env_id, **env_kwargs, **overrides)``, with ``metadata["task"]`` and
        ``metadata["cost_budget"]`` set on the env (a training task's reward is the training
        reward unless ``reward="paper"`` is passed)."""
        import satenv

        env = satenv.make(self.env_id, **{**self.env_kwargs, **overrides})
        env.metadata = {**env.metadata, "task": self.name, "cost_budget": self.cost_budget}
        return env


_ISS_INCLINATION = math.radians(51.6)
_TABLE1_NOTE = ("the Table I formation puts followers closer than 2 r_f, so collisions are counted "
                "but do not end the episode or void success")
_TPLF30 = {"preset": "pereira2023", "topology": "TPLF", "desired_error": (0.0, -30.0, 0.0, 0.0, 0.0, 0.0),
           "terminate_on_collision": True}
_TRAINING = {"reward": "training"}
_NAV = ("nav-0.1m", "nav-1m")
_TRANSLATION = (*_NAV, "thrust-80")


def _platoon(name: str, description: str, *, system: str | None = None, role: str = "extra",
             perturbations: tuple[str, ...] = (), **kwargs: Any) -> Task:
    """A platoon_v0 task; pereira2023 Table I ones count collisions without ending the episode
    (their target formation is closer than 2 r_f, so the paper sets no collision constraint)."""
    table1 = kwargs.get("preset") == "pereira2023" and not kwargs.get("terminate_on_collision", True)
    return Task(name, "platoon_v0", kwargs, system, role, description, perturbations,
                None if table1 else 0.0)


def _tasks() -> list[Task]:
    tasks = _registered()
    by_name = {t.name: t for t in tasks}
    return tasks + [_rung(by_name[SYSTEMS[system].training_task], prefix, k, label, what, changes)
                    for system, (prefix, rungs) in _ladder_rungs().items()
                    for k, (label, what, changes) in enumerate(rungs, start=1)]


def _rung(base: Task, prefix: str, k: int, label: str, what: str, changes: Mapping[str, Any]) -> Task:
    """Rung ``k`` of ``base``'s ladder: its task with ``changes`` (never the physics)."""
    return Task(f"{prefix}-rung{k}-{label}", base.env_id, {**base.env_kwargs, **changes}, base.system, "extra",
                f"ladder rung {k} of {base.name}: {what}", (), base.cost_budget)


def _rows(array: Any) -> tuple[tuple[float, ...], ...]:
    """An array's rows as a tuple of float tuples (a frozen env keyword)."""
    return tuple(tuple(float(v) for v in row) for row in array)


def _ladder_rungs() -> dict[str, tuple[str, tuple[tuple[str, str, dict[str, Any]], ...]]]:
    """Per system: the rungs' name prefix and, easiest first, each rung's label, what it changes
    and its env keywords on top of the training task's (the training task is the last rung)."""
    from satenv.scenarios.cluster import resolve_scenario as resolve_cluster
    from satenv.scenarios.platoon import resolve_scenario

    def platoon(preset: str, **kwargs: Any) -> tuple[tuple[str, str, dict[str, Any]], ...]:
        """Starts drawn around the targets, then around the points halfway from the targets to the
        paper's start (the training task draws around the paper's start, within 20 m per axis)."""
        scenario = resolve_scenario(preset, **kwargs)
        targets = scenario.desired_states()
        return (("near", "starts drawn within 5 m (per axis) of the targets",
                 {"initial_state": _rows(targets), "random_position_spread": 5.0}),
                ("half", "starts drawn within 10 m (per axis) of the points halfway from the targets to "
                 "the paper's start", {"initial_state": _rows((targets + scenario.initial_array()) / 2.0),
                                       "random_position_spread": 10.0}))

    def formation() -> tuple[tuple[str, str, dict[str, Any]], ...]:
        coarse = {"dt": 0.2, "max_steps": 100, "success_tol": 10.0}   # the same 20 s, 100 decisions
        return (("near", "starts drawn around the target formation; a decision every 0.2 s (100 per 20 s "
                 "episode); success tolerance 10 m", {"random_start": "target", **coarse}),
                ("coarse", "a decision every 0.2 s (100 per 20 s episode); success tolerance 10 m", coarse))

    def servicing() -> tuple[tuple[str, str, dict[str, Any]], ...]:
        first = {"dt": 0.5, "substeps": 5, "max_steps": 80, "success_tol": 2.0}   # physics step 0.1 s kept
        return (("near", "starts 1-3 m outside the keep-out sphere within 0.2 rad of the first waypoint; the "
                 "first waypoint only (40 s), a decision every 0.5 s; success tolerance 2 m",
                 {"random_shell": 2.0, "random_cone": 0.2, **first}),
                ("first", "the first waypoint only (40 s), a decision every 0.5 s; success tolerance 2 m", first))

    def cluster() -> tuple[tuple[str, str, dict[str, Any]], ...]:
        near = {"random_start": "slots", "random_position_spread": 100.0, "dt": 10.0, "max_steps": 50,
                "success_tol": 10.0}   # physics step 0.25 s kept
        three = tuple(tuple(p) for p in resolve_cluster("li2022-case1").initial_positions[:3])
        return (("near3", "3 satellites, starts within 100 m (per axis) of their slots; 500 s, a decision every "
                 "10 s; success tolerance 10 m", {"initial_positions": three, **near}),
                ("near", "starts within 100 m (per axis) of the slots; 500 s, a decision every 10 s; success "
                 "tolerance 10 m", near))

    tplf30 = {k: v for k, v in _TPLF30.items() if k != "preset"}
    return {
        "platoon-pereira2023": ("platoon-tplf30", platoon("pereira2023", **tplf30)),
        "platoon-pereira2022": ("platoon-pereira2022", platoon("pereira2022")),
        "cluster-li2022": ("cluster-case1", cluster()),
        "servicing-pereira2022": ("servicing-pereira2022", servicing()),
        "formation-kannan2022-position": ("formation-kannan2022-position", formation()),
        "formation-kannan2022-collision": ("formation-kannan2022-collision", formation()),
    }


def _registered() -> list[Task]:
    from satenv.scenarios import cluster as _cluster
    from satenv.scenarios.platoon import resolve_scenario, swarm

    return [
        *[_platoon(f"platoon-{topo}-{dyn}",
                   f"pereira2023 Table I, {topo} topology, {dyn} truth"
                   + (" (chief inclination 51.6 deg)" if dyn == "j2" else "") + f"; {_TABLE1_NOTE}",
                   system="platoon-pereira2023" if (topo, dyn) == ("PLF", "cw") else None,
                   role="paper" if (topo, dyn) == ("PLF", "cw") else "extra",
                   preset="pereira2023", topology=topo, dynamics=dyn, terminate_on_collision=False,
                   **({"inclination": _ISS_INCLINATION} if dyn == "j2" else {}))
          for dyn in ("cw", "j2") for topo in ("PLF", "BDL", "TPLF")],
        _platoon("platoon-random-cw", f"pereira2023 PLF with randomised initial states, cw; {_TABLE1_NOTE}",
                 preset="pereira2023", randomize=True, terminate_on_collision=False),
        _platoon("platoon-random-j2", f"pereira2023 PLF with randomised initial states, j2 (51.6 deg); "
                 f"{_TABLE1_NOTE}", preset="pereira2023", randomize=True, dynamics="j2",
                 inclination=_ISS_INCLINATION, terminate_on_collision=False),
        _platoon("platoon-chain-cw", "pereira2023 Table I start, PLF, chain formation (followers 8 m "
                 "apart, collision-free target); a collision ends the episode",
                 preset="pereira2023", formation="chain", terminate_on_collision=True),
        _platoon("platoon-tplf30-random-cw", "pereira2023 TPLF with E_d = [0, -30, 0] (targets 8-15 m "
                 "apart, collision-free) and randomised initial states, cw; a collision ends the episode",
                 system="platoon-pereira2023", role="training",
                 perturbations=(*_TRANSLATION, "model-j2"), **_TPLF30, randomize=True, **_TRAINING),
        _platoon("platoon-tplf30-near10", "platoon-tplf30-random-cw with starts drawn within 10 m (per axis) "
                 "of the targets: neighbours 8.3 m apart at their targets start out of order, so learners "
                 "collide more than on the training task (a former ladder rung; its tuned PPO configuration "
                 "is satenv/training/rl/tuned/platoon-tplf30-near10.json)",
                 **_TPLF30, randomize=True, **_TRAINING, random_position_spread=10.0,
                 initial_state=_rows(resolve_scenario(**_TPLF30).desired_states())),
        _platoon("platoon-pereira2022", "pereira2022 §5.1: 2 followers in a chain, keep-out sphere, "
                 "LOS cone (collision-free success)", system="platoon-pereira2022", role="paper",
                 preset="pereira2022"),
        _platoon("platoon-swarm256-ring-cw", "swarm of 256 followers on a ring 20 m apart, each hearing "
                 "its two ring neighbours (RING), randomised starts within 4 m of the targets, cw; a "
                 "collision ends the episode (satenv.scenarios.platoon.swarm)", **swarm(256, "ring", "RING")),
        _platoon("platoon-pereira2022-random", "pereira2022 §5.1 with randomised initial states (inside "
                 "the LOS cone, outside the keep-out sphere)", system="platoon-pereira2022",
                 role="training", perturbations=(*_TRANSLATION, "model-j2"),
                 preset="pereira2022", randomize=True, **_TRAINING),
        Task("cluster-case1", "cluster_v0", {"preset": "li2022-case1"}, "cluster-li2022", "paper",
             "li2022 case 1: 10 satellites, moving obstacle, J2 + drag + disturbance"),
        Task("cluster-case2", "cluster_v0", {"preset": "li2022-case2"}, None, "extra",
             "li2022 case 2: 10 satellites, moving obstacle, J2 + drag + disturbance"),
        Task("cluster-case1-random", "cluster_v0", {"preset": "li2022-case1", "randomize": True, **_TRAINING},
             "cluster-li2022", "training",
             "li2022 case 1 with randomised starts (±50 m) and target slots (on the 300 m sphere)",
             (*_TRANSLATION, "disturbance-x2", "model-cw")),
        *[Task(f"cluster-swarm{n}", "cluster_v0", _cluster.swarm(n), None, "extra",
               f"li2022 case-1 physics (J2 + drag, disturbance, moving obstacle) with {n} satellites and "
               f"{n} slots, random each reset (satenv.scenarios.cluster.swarm): a team-size ladder for "
               "policies trained at one size") for n in (10, 20, 40)],
        Task("cluster-swarm64-cw", "cluster_v0", _cluster.swarm(64, dynamics="cw"), None, "extra",
             "li2022 case-1 physics with 64 satellites and 64 slots (random each reset, Hungarian "
             "allocation), cw truth (satenv.scenarios.cluster.swarm)"),
        Task("servicing-pereira2022", "servicing_v0", {"preset": "pereira2022"},
             "servicing-pereira2022", "paper", "pereira2022 §5.2: 6-DOF servicing around a passive object"),
        Task("servicing-pereira2022-random", "servicing_v0", {"preset": "pereira2022", "randomize": True, **_TRAINING},
             "servicing-pereira2022", "training",
             "pereira2022 §5.2 with randomised initial states (every start at least 1 m outside the "
             "keep-out sphere)", (*_TRANSLATION, "inertia-x1.5", "inertia-x0.5")),
        Task("formation-kannan2022-position", "formation_v0", {"preset": "kannan2022-position"},
             "formation-kannan2022-position", "paper", "kannan2022 §5.1: 3 spacecraft to a connected "
             "in-plane network"),
        Task("formation-kannan2022-collision", "formation_v0", {"preset": "kannan2022-collision"},
             "formation-kannan2022-collision", "paper", "kannan2022 §5.2: leader-follower y-spacing of 10 m"),
        Task("formation-kannan2022-position-random", "formation_v0",
             {"preset": "kannan2022-position", "randomize": True, **_TRAINING}, "formation-kannan2022-position",
             "training", "kannan2022 §5.1 with randomised starts (±20 m, ±1 m/s around the origin)",
             (*_TRANSLATION, "model-j2")),
        Task("formation-kannan2022-collision-random", "formation_v0",
             {"preset": "kannan2022-collision", "randomize": True, **_TRAINING}, "formation-kannan2022-collision",
             "training", "kannan2022 §5.2 with randomised starts (±20 m, ±1 m/s around the origin)",
             (*_TRANSLATION, "model-j2")),
    ]


TASKS: Mapping[str, Task] = MappingProxyType({t.name: t for t in _tasks()})
"""Every task by name (the scoreboard's scenarios)."""

LADDERS: Mapping[str, tuple[str, ...]] = MappingProxyType({
    s: (*(t.name for t in TASKS.values() if t.system == s and "-rung" in t.name), SYSTEMS[s].training_task)
    for s in SYSTEMS})
"""Per system, its ladder's task names, easiest first, ending at its training task (:func:`ladder`)."""


def names() -> tuple[str, ...]:
    """Every task name, registry order."""
    return tuple(TASKS)


def get(name: str) -> Task:
    """The task called ``name`` (a system's tasks: :func:`training_task`, :func:`paper_task`)."""
    if not isinstance(name, str) or name not in TASKS:
        raise SatenvError(f"unknown task {name!r:.80}; expected one of {list(TASKS)}")
    return TASKS[name]


def system(name: str) -> System:
    """The paper system called ``name``."""
    if not isinstance(name, str) or name not in SYSTEMS:
        raise SatenvError(f"unknown system {name!r:.80}; expected one of {list(SYSTEMS)}")
    return SYSTEMS[name]


def training_task(system_name: str) -> Task:
    """The system's training task (randomised start from the seed)."""
    return TASKS[system(system_name).training_task]


def ladder(system_name: str) -> tuple[str, ...]:
    """The system's ladder: task names, easiest first, ending at its training task. A rung
    changes where the starts are drawn, the number of agents, the success tolerance, the horizon or
    the decision period, never the physics."""
    return LADDERS[system(system_name).name]


def paper_task(system_name: str) -> Task:
    """The system's paper task (the paper's start, deterministic)."""
    return TASKS[system(system_name).paper_task]


def _check_registry() -> None:
    for s in SYSTEMS.values():
        for name, role in ((s.training_task, "training"), (s.paper_task, "paper")):
            t = TASKS[name]
            if t.system != s.name or t.role != role:
                raise SatenvError(f"system {s.name}: task {name} must have system={s.name!r} and "
                                  f"role={role!r}, has {t.system!r} and {t.role!r}")
        if not TASKS[s.training_task].randomized:
            raise SatenvError(f"system {s.name}: its training task must randomise the start")


_check_registry()
