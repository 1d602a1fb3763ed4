"""PPO-Lagrangian for the lean learner: a dual variable on the episode safety cost.

The constrained problem is ``max J_r`` subject to ``J_c <= d``, with ``J_c`` the expected episode
safety cost of an agent (the env's ``safety_cost`` info summed over the episode) and ``d`` the
task's ``cost_budget``. Its Lagrangian relaxation ``max_pi min_{lam >= 0} J_r - lam (J_c - d)``
is solved by alternating (Ray, Achiam and Amodei 2019, Safety Gym's PPO-Lagrangian):

* the policy step is PPO on the penalised reward ``(r - lam c) / (1 + lam)`` (GAE is linear in the
  rewards, so the penalty ``lam`` times the cost's advantage is subtracted from the advantage; the
  ``1 / (1 + lam)`` keeps its scale); ``r`` is the normalised training reward, so ``lam`` is in units
  of it;
* the dual step is projected gradient ascent after each iteration,
  ``lam <- max(0, lam + lr (mean episode cost - d))`` over the episodes that finished in it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Lagrange"]


@dataclass
class Lagrange:
    """The dual variable ``lam`` and its update (module docstring)."""

    budget: float
    """``d``: the episode safety-cost budget per agent (the task's ``cost_budget``)."""
    lr: float = 0.05
    """Dual step size, in normalised-reward units per unit of episode cost."""
    lam: float = 0.0

    def __post_init__(self) -> None:
        for name in ("budget", "lr", "lam"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not (math.isfinite(v) and v >= 0):
                raise ValueError(f"Lagrange {name} must be a finite number >= 0, got {v!r}")

    def penalise(self, rewards: np.ndarray, cost: np.ndarray) -> np.ndarray:
        """``(r - lam c) / (1 + lam)`` of one step's ``(B, M)`` rewards and safety costs."""
        return ((rewards - self.lam * np.asarray(cost, dtype=np.float64)) / (1.0 + self.lam)).astype(rewards.dtype)

    def update(self, episode_costs: Sequence[float]) -> float:
        """One dual step on the finished episodes' costs (no episode: no step); returns ``lam``."""
        if len(episode_costs):
            self.lam = max(0.0, self.lam + self.lr * (float(np.mean(episode_costs)) - self.budget))
        return self.lam
