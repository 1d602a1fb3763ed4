"""The grid of the reference results: which runs, on which rung, at which budget, evaluated where.

A :class:`Run` is one ``(rung, algorithm, filter in training, seed)`` training run on a task of the
system's ladder (:func:`satenv.tasks.ladder`: easiest first, ending at the system's training task).
It is evaluated at :data:`CHECKPOINTS` evenly spaced checkpoints: the intermediate ones on the first
:data:`CURVE_TEST_SEEDS` test seeds of the rung (the learning curves), the last one on the first
:data:`FINAL_TEST_SEEDS`; the same seeds for every algorithm and the controller. Every checkpoint is
also flown on the rung's first :data:`VALIDATION_SEEDS` validation seeds, and the published result is
the checkpoint :func:`select_checkpoint` picks there (early stopping on validation seeds: a policy
that drifts late in training is reported at its best validation point), flown on the
:data:`FINAL_TEST_SEEDS` test seeds (one more record, checkpoint index :attr:`Run.selected_index`).
Nothing is chosen on test seeds: the algorithms run at their defaults. The controller of the system is
one more run per rung (``algorithm="controller"``, no training, nothing to select).

Budgets are agent-steps (one agent's one decision; BenchMARL frames are converted, one frame = every
agent of one env copy acting once), the same for every RL algorithm of a system
(:data:`BUDGET_AGENT_STEPS`), MASAC's smaller (:data:`MASAC_BUDGET_AGENT_STEPS`: its gradient steps
are the cost); DAgger's budget is expert labels (:data:`DAGGER_LABELS`).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import asdict, dataclass
from typing import Any

from satenv import tasks

__all__ = ["VALIDATION_SEEDS", "select_checkpoint",
           "ALGORITHMS", "BUDGET_AGENT_STEPS", "CHECKPOINTS", "CURVE_TEST_SEEDS", "DAGGER_LABELS", "DEFAULT_ALGORITHMS",
           "DEFAULT_SEEDS", "FILTER_PENALTY", "FINAL_TEST_SEEDS", "KEY", "MASAC_BATCH", "MASAC_BUDGET_AGENT_STEPS",
           "MASAC_UTD", "grid_budget", "RL_ALGORITHMS", "Run", "LearningError", "grid", "test_seeds"]


class LearningError(ValueError):
    """A bad grid or log entry (names the field, the value and what is expected)."""


RL_ALGORITHMS = ("ppo", "ippo", "mappo", "ppo_lag", "masac")
"""The RL rows: the lean learner's PPO (parameter-shared), IPPO and MAPPO and PPO-Lagrangian
(``satenv.training.rl``), BenchMARL's MASAC (``satenv.training.benchmarl_train``)."""
ALGORITHMS = (*RL_ALGORITHMS, "dagger", "controller")
"""Every row of the grid; ``controller`` is the system's controller (no training, the reference)."""
DEFAULT_ALGORITHMS = ("controller", "ppo", "ippo", "mappo", "ppo_lag", "masac", "dagger")
"""The rows run by default."""
STANDARD_RL = ("ppo", "ippo", "mappo", "masac")
"""The standard (unconstrained) RL rows."""

DEFAULT_SEEDS = (0, 1, 2, 3, 4)
"""Training seeds of every row."""

CHECKPOINTS = 5
"""Evaluations per run, at 1/5, 2/5, ..., 5/5 of the budget (the last one is the test result)."""
CURVE_TEST_SEEDS = 10
"""Test seeds of an intermediate evaluation (a point of the learning curve)."""
FINAL_TEST_SEEDS = 20
"""Test seeds of the final evaluation and of the selected checkpoint's (the published result)."""
VALIDATION_SEEDS = 20
"""Validation seeds every checkpoint is flown on to select the published one (:func:`select_checkpoint`)."""

BUDGET_AGENT_STEPS: dict[str, int] = {
    "platoon-pereira2023": 10_000_000,
    "platoon-pereira2022": 10_000_000,
    "formation-kannan2022-position": 10_000_000,
    "formation-kannan2022-collision": 10_000_000,
    "cluster-li2022": 10_000_000,
    "servicing-pereira2022": 10_000_000,
}
"""RL budget of every rung of each system [agent-steps]."""

DAGGER_LABELS: dict[str, int] = {
    "platoon-pereira2023": 14_400,
    "platoon-pereira2022": 12_000,
    "formation-kannan2022-position": 30_000,
    "formation-kannan2022-collision": 30_000,
    "cluster-li2022": 20_000,
    "servicing-pereira2022": 12_000,
}
"""DAgger's budget of expert labels (agent-steps labelled by the expert): :data:`CHECKPOINTS` rounds
of ``satenv.bench.learning.trainers.DAGGER_EPISODES`` whole episodes; the expert's speed sets it."""

MASAC_UTD = 0.25
"""MASAC's update-to-data ratio: gradient steps per frame (BenchMARL's off-policy optimiser steps
per collected frame)."""
MASAC_BATCH = 128
"""MASAC's frames per gradient step: BenchMARL's standard ``off_policy_train_batch_size``
(``benchmarl/conf/experiment/base_experiment.yaml``)."""
MASAC_BUDGET_AGENT_STEPS = 1_000_000
"""MASAC's budget on every rung [agent-steps]: at :data:`MASAC_UTD` and :data:`MASAC_BATCH` a
BenchMARL gradient step costs about 6 ms on these shared cores (measured on the TPLF platoon's first
rung: 2,560 more gradient steps took 15.5 s more, load average 2.5-2.9), so 10 M agent-steps (625,000
gradient steps on the platoon) would take about an hour per run and 30 hours per rung of five seeds
on the six systems; the page states it."""

FILTER_SYSTEMS = ("cluster-li2022", "servicing-pereira2022", "platoon-pereira2022")
"""The systems whose PPO row is run once more with the safety filter in the training env."""
FILTER_PENALTY = 0.1
"""Reward penalty per unit of filter correction ``|du|`` in the filtered training env
(``satenv.safety.SafetyConfig.penalty``)."""

KEY = ("task", "algorithm", "filter", "seed", "budget_agent_steps", "checkpoint")
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
    """RL agent-steps instead of :data:`BUDGET_AGENT_STEPS` (0: the grid's budget)."""
    rung: str = ""
    """The ladder task the run trains and is tested on ('': the system's training task)."""

    def __post_init__(self) -> None:
        tasks.system(self.system)
        if self.rung and self.rung not in tasks.ladder(self.system):
            raise LearningError(f"rung must be a task of {self.system}'s ladder {list(tasks.ladder(self.system))}, "
                                f"got {self.rung!r}")
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
        return tasks.get(self.rung) if self.rung else tasks.training_task(self.system)

    @property
    def rung_index(self) -> int:
        """1 for the ladder's first (easiest) rung."""
        return tasks.ladder(self.system).index(self.task.name) + 1

    @property
    def budget(self) -> int:
        """Agent-steps (RL), expert labels (DAgger) or 0 (controller)."""
        if self.algorithm == "controller":
            return 0
        if self.algorithm == "dagger":
            return DAGGER_LABELS[self.system]
        return self.budget_override or grid_budget(self.system, self.algorithm)

    @property
    def checkpoints(self) -> list[int]:
        """The budget at each evaluation (``[0]`` for the controller)."""
        if self.algorithm == "controller":
            return [0]
        return [round(self.budget * (k + 1) / CHECKPOINTS) for k in range(CHECKPOINTS)]

    @property
    def selects(self) -> bool:
        """Whether the run has a selected checkpoint (every trained run; not the controller)."""
        return self.algorithm != "controller"

    @property
    def selected_index(self) -> int:
        """The checkpoint index of the selected checkpoint's record (one past the last checkpoint)."""
        return len(self.checkpoints)

    @property
    def records(self) -> range:
        """The checkpoint indices of the run's log records: each checkpoint, then the selected one."""
        return range(len(self.checkpoints) + self.selects)

    def seeds(self, k: int) -> tuple[int, ...]:
        """The test seeds of record ``k`` (:data:`FINAL_TEST_SEEDS` at the last checkpoint and the selected one)."""
        return test_seeds(self.task.name, k >= len(self.checkpoints) - 1)

    def validation_seeds(self) -> tuple[int, ...]:
        """The validation seeds every checkpoint is flown on (:data:`VALIDATION_SEEDS`)."""
        return self.task.seeds("validation", VALIDATION_SEEDS)

    def key(self, checkpoint: int) -> tuple[Any, ...]:
        return (self.task.name, self.algorithm, self.filter, self.seed, self.budget, checkpoint)

    @property
    def longer(self) -> bool:
        """An RL run at a budget other than the grid's (``--budget``): its own row on the page."""
        return self.algorithm in RL_ALGORITHMS and self.budget != grid_budget(self.system, self.algorithm)

    def label(self) -> str:
        budget = f"@{self.budget}" if self.longer else ""
        return f"{self.task.name}/{self.algorithm}{'+filter' if self.filter else ''}{budget}/seed{self.seed}"

    def to_json(self) -> dict[str, Any]:
        return {**{k: v for k, v in asdict(self).items() if k not in ("log_path", "budget_override", "rung")},
                "task": self.task.name}


def select_checkpoint(validations: list[dict[str, Any]]) -> int:
    """The index of the checkpoint to publish from each checkpoint's validation summary
    (``{"success": int, "unsafe": int}``: successful episodes, and episodes with a collision or a
    hard-bound violation): the most successes, then the fewest unsafe episodes, then the latest."""
    if not validations:
        raise LearningError("select_checkpoint needs at least one checkpoint's validation summary, got none")
    return max(range(len(validations)),
               key=lambda k: (validations[k]["success"], -validations[k]["unsafe"], k))


def grid_budget(system: str, algorithm: str) -> int:
    """The grid's budget of a row: agent-steps (RL), expert labels (DAgger), 0 (controller)."""
    if algorithm == "controller":
        return 0
    if algorithm == "dagger":
        return DAGGER_LABELS[system]
    return MASAC_BUDGET_AGENT_STEPS if algorithm == "masac" else BUDGET_AGENT_STEPS[system]


def test_seeds(task: str, final: bool = True) -> tuple[int, ...]:
    """The test seeds of an evaluation on ``task`` (final: :data:`FINAL_TEST_SEEDS`, else
    :data:`CURVE_TEST_SEEDS`; the curve's are the first of the final's)."""
    return tasks.get(task).seeds("test", FINAL_TEST_SEEDS if final else CURVE_TEST_SEEDS)


def grid(systems: Iterable[str], algorithms: Iterable[str], seeds: Iterable[int],
         filter_systems: Iterable[str] = FILTER_SYSTEMS, filter_algorithm: str = "ppo",
         log_path: str = "", budget: int = 0, rungs: Iterable[int] | None = None) -> list[Run]:
    """Every run: per system and rung (``rungs``: 1-based indices of the ladder, default all; easiest
    first), the controller once, then each algorithm x seed, then the filter-in-training row
    (``filter_algorithm``) on ``filter_systems``; systems in the order given."""
    algorithms, seeds, filt = list(algorithms), list(seeds), set(filter_systems)
    runs = []
    for system in systems:
        ladder = tasks.ladder(system)
        picked = list(rungs) if rungs is not None else list(range(1, len(ladder) + 1))
        bad = [i for i in picked if not 1 <= i <= len(ladder)]
        if bad:
            raise LearningError(f"rungs {bad}: {system}'s ladder has rungs 1-{len(ladder)}")
        for rung in (ladder[i - 1] for i in picked):
            if "controller" in algorithms:
                runs.append(Run(system, "controller", False, 0, log_path, budget, rung))
            for seed in seeds:
                runs += [Run(system, a, False, seed, log_path, budget, rung) for a in algorithms if a != "controller"]
                if system in filt and filter_algorithm in algorithms:
                    runs.append(Run(system, filter_algorithm, True, seed, log_path, budget, rung))
    return runs
