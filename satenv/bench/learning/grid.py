"""The grid of the reference results: which runs, at which budget, evaluated where.

A :class:`Run` is one ``(system, algorithm, filter in training, seed)`` training run on the
system's training task (:func:`satenv.tasks.training_task`); it is evaluated at
:data:`CHECKPOINTS` evenly spaced checkpoints on the first :data:`TEST_SEEDS_PER_CHECKPOINT` test
seeds of the task (the same seeds every checkpoint, every algorithm and the controller). The
controller of the system is one more run (``algorithm="controller"``, no training) on the same
seeds: the horizontal line of the figures and the reference of the RMSE and delta-v ratios.

Budgets (:data:`BUDGET_AGENT_STEPS`) are agent-steps, the same for every RL algorithm of a task
(SB3 counts agent-steps; BenchMARL frames are converted, one frame = every agent of one env copy
acting once); DAgger's budget is expert labels (one label = one agent-step labelled by the
expert), :data:`DAGGER_LABELS`. They are small: the grid was sized for 2 shared CPU cores.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import asdict, dataclass
from typing import Any

from satenv import tasks

__all__ = ["ALGORITHMS", "BUDGET_AGENT_STEPS", "CHECKPOINTS", "DAGGER_LABELS", "DEFAULT_SEEDS", "FILTER_SYSTEMS", "KEY",
           "RL_ALGORITHMS", "Run", "TEST_SEEDS_PER_CHECKPOINT", "LearningError", "grid", "test_seeds"]


class LearningError(ValueError):
    """A bad grid or log entry (names the field, the value and what is expected)."""


RL_ALGORITHMS = ("ppo", "mappo", "ippo", "masac", "isac")
"""The RL rows: SB3 PPO (parameter-shared, ``satenv.training.train``) and BenchMARL's MAPPO, IPPO, MASAC
and ISAC (``satenv.training.benchmarl_train``)."""
ALGORITHMS = (*RL_ALGORITHMS, "dagger", "controller")
"""Every row of the grid; ``controller`` is the system's controller (no training, the reference)."""
DEFAULT_ALGORITHMS = ("controller", "ppo", "mappo", "masac", "dagger")
"""The rows run by default (IPPO and ISAC on request: ``--algorithms``)."""

DEFAULT_SEEDS = (0, 1, 2)
"""Training seeds of every row."""

CHECKPOINTS = 5
"""Evaluations per run, at 1/5, 2/5, ..., 5/5 of the budget (the last one is the test result)."""
TEST_SEEDS_PER_CHECKPOINT = 5
"""Test seeds of each evaluation: the first five of the task's test split (900000-900004)."""

BUDGET_AGENT_STEPS: dict[str, int] = {
    "platoon-pereira2023": 200_000,
    "platoon-pereira2022": 200_000,
    "formation-kannan2022-position": 200_000,
    "formation-kannan2022-collision": 200_000,
    "cluster-li2022": 200_000,
    "servicing-pereira2022": 200_000,
}
"""RL budget of each system's training task [agent-steps]."""

DAGGER_LABELS: dict[str, int] = {
    "platoon-pereira2023": 14_400,
    "platoon-pereira2022": 12_000,
    "formation-kannan2022-position": 30_000,
    "formation-kannan2022-collision": 30_000,
    "cluster-li2022": 20_000,
    "servicing-pereira2022": 12_000,
}
"""DAgger's budget of expert labels (agent-steps labelled by the expert): :data:`CHECKPOINTS` rounds
of ``satenv.bench.learning.trainers.DAGGER_EPISODES`` whole episodes (agents x episode steps labels
each); the expert's speed sets it (the servicing NMPC labels a few agent-steps per second)."""

FILTER_SYSTEMS = ("cluster-li2022", "servicing-pereira2022", "platoon-pereira2022")
"""The systems whose PPO row is run once more with the safety filter in the training env."""
FILTER_PENALTY = 0.1
"""Reward penalty per unit of filter correction ``|du|`` in the filtered training env
(``satenv.safety.SafetyConfig.penalty``)."""

KEY = ("system", "algorithm", "filter", "seed", "budget_agent_steps", "checkpoint")
"""The key of a log record: one evaluation of one run (a run at another budget, ``--budget``, is
another run)."""


@dataclass(frozen=True)
class Run:
    """One training run of the grid (or the controller's evaluation, ``algorithm="controller"``)."""

    system: str
    algorithm: str
    filter: bool = False
    seed: int = 0
    log_path: str = ""
    budget_override: int = 0
    """RL agent-steps instead of :data:`BUDGET_AGENT_STEPS` (0: the grid's budget; smoke tests)."""

    def __post_init__(self) -> None:
        tasks.system(self.system)
        if self.algorithm not in ALGORITHMS:
            raise LearningError(f"algorithm must be one of {list(ALGORITHMS)}, got {self.algorithm!r}")
        if not isinstance(self.filter, bool):
            raise LearningError(f"filter must be a bool, got {self.filter!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise LearningError(f"seed must be an int >= 0, got {self.seed!r}")
        if isinstance(self.budget_override, bool) or not isinstance(self.budget_override, int) \
                or self.budget_override < 0:
            raise LearningError(f"budget must be an int >= 0 agent-steps (0: the grid's), got {self.budget_override!r}")

    @property
    def task(self) -> tasks.Task:
        return tasks.training_task(self.system)

    @property
    def budget(self) -> int:
        """Agent-steps (RL), expert labels (DAgger) or 0 (controller)."""
        if self.algorithm == "controller":
            return 0
        if self.algorithm == "dagger":
            return DAGGER_LABELS[self.system]
        return self.budget_override or BUDGET_AGENT_STEPS[self.system]

    @property
    def checkpoints(self) -> list[int]:
        """The budget at each evaluation (``[0]`` for the controller)."""
        if self.algorithm == "controller":
            return [0]
        return [round(self.budget * (k + 1) / CHECKPOINTS) for k in range(CHECKPOINTS)]

    def key(self, checkpoint: int) -> tuple[Any, ...]:
        return (self.system, self.algorithm, self.filter, self.seed, self.budget, checkpoint)

    @property
    def longer(self) -> bool:
        """An RL run at a budget other than the grid's (``--budget``): its own row on the page."""
        return self.algorithm in RL_ALGORITHMS and self.budget != BUDGET_AGENT_STEPS[self.system]

    def label(self) -> str:
        budget = f"@{self.budget}" if self.longer else ""
        return f"{self.system}/{self.algorithm}{'+filter' if self.filter else ''}{budget}/seed{self.seed}"

    def to_json(self) -> dict[str, Any]:
        return {k: v for k, v in asdict(self).items() if k not in ("log_path", "budget_override")}


def test_seeds(system: str) -> tuple[int, ...]:
    """The test seeds every evaluation of ``system`` uses."""
    return tasks.training_task(system).seeds("test", TEST_SEEDS_PER_CHECKPOINT)


def grid(systems: Iterable[str], algorithms: Iterable[str], seeds: Iterable[int],
         filter_systems: Iterable[str] = FILTER_SYSTEMS, filter_algorithm: str = "ppo",
         log_path: str = "", budget: int = 0) -> list[Run]:
    """Every run: per system, the controller once, then each algorithm x seed, then the
    filter-in-training row (``filter_algorithm``) on ``filter_systems``; cheap systems first
    (the order of ``systems``)."""
    algorithms, seeds, filt = list(algorithms), list(seeds), set(filter_systems)
    runs = []
    for system in systems:
        if "controller" in algorithms:
            runs.append(Run(system, "controller", False, 0, log_path, budget))
        for seed in seeds:
            runs += [Run(system, a, False, seed, log_path, budget) for a in algorithms if a != "controller"]
            if system in filt and filter_algorithm in algorithms:
                runs.append(Run(system, filter_algorithm, True, seed, log_path, budget))
    return runs
