"""The training reward and the per-agent safety cost, one home for every env, ``make_vec`` and TorchRL.

Every env takes ``reward=`` (:data:`REWARDS`): ``"paper"`` (the default of ``satenv.make``) keeps
the paper's stage cost, what the reproductions and the board's paper metrics use; ``"training"``
(the default of a training task's env, :mod:`satenv.tasks`) replaces it with a reward that points
at success. Per agent ``i`` and step, with ``d_i`` the distance to its target (the norm of the
position part of ``tracking_error``, the quantity :func:`satenv.metrics.success` judges)::

    r_i = phi(d_i') - phi(d_i)                       progress (potential-based, telescopes)
        + IN_TOLERANCE_BONUS (1 - d_i' / tol) / H  [d_i' <= tol]   bonus inside the success tolerance
        + SUCCESS_BONUS           [the team succeeds at the last step]
        - PENALTY [agent i's first collision]  - PENALTY [its first hard-bound violation]
        - PENALTY [agent i left the region]

with the potential ``phi(d) = -log(1 + d / tol) / log(1 + reach / tol)`` in ``[-1, 0]`` inside
the region (``reach = 2 max_distance``, the farthest a target can be from an agent still in the
region) and ``H`` the horizon (``max_steps``). The bonus grows with the depth inside the
tolerance, so the best policy keeps a margin instead of resting on the tolerance's edge. With a
flat bonus, the reference grid's lean PPO solved the platoons by 2 M agent-steps and then drifted to
a median final error of 1.0-1.2 m against the 1 m tolerance by 10 M, on 3 of 5 training seeds of
the TPLF training task and of the section 5.1 platoon's first rung (its log:
``studies/reference_results/flat_bonus_log.jsonl``); the graded bonus was then checked on
validation seeds only (700000-700019): the two seeds of the latter that had drifted held 20/20 at
10 M (final error 0.32 m and 0.63 m). The sizes are derived, not tuned:

* without the success bonus an agent gains at most :data:`EARNABLE` (the potential's span, 1,
  plus the whole in-tolerance bonus), over a whole episode or over any rest of one;
* :data:`PENALTY` exceeds that: from any state, a collision, a violation or leaving the region
  costs more than all the progress and bonus the agent could still collect (and a collision that
  voids success, or leaving, which ends the episode, also forfeits the success bonus);
* :data:`SUCCESS_BONUS` exceeds ``EARNABLE + PENALTY`` plus the potential left inside the
  tolerance, so every successful episode, even one whose agents each paid a violation penalty,
  out-scores every failing one, whatever either's start.

Each kind of penalty is charged once per agent and episode (at its first event), which keeps that
ordering exact; every step of a collision or violation is counted in ``safety_cost`` (per agent
and step, 1.0 on a collision or a hard-bound violation, else 0.0; Safety-Gymnasium's convention),
the constrained-RL signal, in the infos under either reward beside the env's own ``cost``; a
task's ``cost_budget`` bounds its sum over an episode. Collisions cost without ending the episode
where the task does not end it; termination stays the env's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from satenv.errors import SatenvError, SatenvTypeError

__all__ = ["EARNABLE", "IN_TOLERANCE_BONUS", "KINDS", "PENALTY", "POTENTIAL_SPAN", "REWARDS", "SUCCESS_BONUS",
           "RewardState", "TrainingReward", "check_reward", "events", "potential", "safety_cost", "target_distance",
           "training_rewards", "with_safety_cost"]

REWARDS = ("paper", "training")
"""The values of every env's ``reward=`` keyword (module docstring)."""

POTENTIAL_SPAN = 1.0
"""``phi`` runs from ``-POTENTIAL_SPAN`` (at ``reach``) to 0 (on the target)."""
IN_TOLERANCE_BONUS = 1.0
"""The most the in-tolerance bonus pays an agent over an episode (at most ``1 / H`` per step
inside: ``(1 - d / tol) / H``)."""
EARNABLE = POTENTIAL_SPAN + IN_TOLERANCE_BONUS
"""The most an agent can gain, over an episode or any rest of one, without the success bonus."""
PENALTY = EARNABLE + POTENTIAL_SPAN
"""Per agent, once per episode for each of its first collision, first hard-bound violation and
leaving the region: more than all the progress and bonus the agent could still gain."""
SUCCESS_BONUS = EARNABLE + PENALTY + POTENTIAL_SPAN
"""Paid to every agent at the last step of a successful episode: more than a failing agent can
earn, plus a violation penalty, plus the potential still left inside the tolerance
(``|phi(tol)| < POTENTIAL_SPAN``)."""
KINDS = ("collision", "violation", "left_region")
"""The penalised events, each charged once per agent and episode."""


def check_reward(reward: Any) -> str:
    """``reward`` if it is one of :data:`REWARDS`, else a clear error naming the value."""
    if not isinstance(reward, str):
        raise SatenvTypeError(f"reward must be one of {list(REWARDS)}, got {type(reward).__name__}")
    if reward not in REWARDS:
        raise SatenvError(f"reward must be one of {list(REWARDS)}, got {reward!r:.40}")
    return reward


@dataclass(frozen=True)
class TrainingReward:
    """The task quantities the training reward is derived from (one scenario)."""

    tol: float              # success tolerance [m]
    reach: float            # farthest target distance of an agent inside the region [m]
    max_distance: float     # radius of the allowed region around the origin [m]
    horizon: int            # max_steps
    voids: bool             # a collision voids success

    @classmethod
    def of(cls, scenario: Any) -> TrainingReward:
        return cls(float(scenario.success_tol), 2.0 * float(scenario.max_distance),
                   float(scenario.max_distance), int(scenario.max_steps), bool(scenario.collision_voids_success))

    @property
    def log_reach(self) -> float:
        return math.log1p(self.reach / self.tol)


def potential(dist: np.ndarray, spec: TrainingReward) -> np.ndarray:
    """``phi(d) = -POTENTIAL_SPAN log(1 + d / tol) / log(1 + reach / tol)``, ``d`` clipped to ``reach``."""
    return np.log1p(np.minimum(dist, spec.reach) / spec.tol) * (-POTENTIAL_SPAN / spec.log_reach)


def _squared_norm3(v: np.ndarray) -> np.ndarray:
    """``|v[..., :3]|^2`` (three products: faster than a reduction over a strided last axis)."""
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    out = x * x
    out += y * y
    out += z * z
    return out


def target_distance(info: dict[str, np.ndarray]) -> np.ndarray:
    """``(B, M)`` distance of each agent to its target [m] (what success judges)."""
    return np.sqrt(_squared_norm3(info["tracking_error"]))


def safety_cost(info: dict[str, np.ndarray]) -> np.ndarray:
    """``(B, M)`` float: 1.0 where an agent collides or violates a hard bound this step."""
    return (np.asarray(info["collision"], dtype=bool) | (np.asarray(info["violations"]) > 0)).astype(np.float64)


def events(spec: TrainingReward, info: dict[str, np.ndarray]) -> np.ndarray:
    """``(B, M, 3)`` bool: the agents' collision, hard-bound violation and leaving the region
    (:data:`KINDS`) in a step."""
    out = np.empty((*info["collision"].shape, len(KINDS)), dtype=bool)
    out[..., 0] = info["collision"]
    np.greater(info["violations"], 0, out=out[..., 1])
    np.greater(_squared_norm3(info["state"]), spec.max_distance ** 2, out=out[..., 2])
    return out


def training_rewards(spec: TrainingReward, phi_before: np.ndarray, charged: np.ndarray,
                     info: dict[str, np.ndarray], terminated: np.ndarray, final: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The training rewards ``(B, M)`` of one step, the new potentials ``(B, M)`` and the new
    ``charged`` ``(B, M, 3)`` (which :data:`KINDS` each agent has paid for this episode).

    ``phi_before`` the potentials before the step, ``info`` the step's info arrays, ``terminated``
    ``(B,)``, ``final`` ``(B,)`` whether this is the episode's last step by the horizon."""
    dist = target_distance(info)
    phi = potential(dist, spec)
    inside = dist <= spec.tol
    hit = events(spec, info)
    fresh = hit & ~charged
    now = charged | hit
    rewards = phi - phi_before
    rewards += inside * (1.0 - dist / spec.tol) * (IN_TOLERANCE_BONUS / spec.horizon)
    rewards -= PENALTY * (fresh[..., 0] + fresh[..., 1].astype(np.float64) + fresh[..., 2])
    if final.any():
        collided = now[..., 0].any(axis=-1)
        success = final & ~terminated & inside.all(axis=-1) & ~(spec.voids & collided)
        rewards += success[:, None] * SUCCESS_BONUS
    return rewards, phi, now


class RewardState:
    """The per-copy memory of the training reward for ``B`` copies: the agents' potentials and
    which penalties each has paid this episode (what :func:`training_rewards` needs)."""

    def __init__(self, spec: TrainingReward, batch: int, n_agents: int) -> None:
        self.spec = spec
        self.phi = np.zeros((batch, n_agents))
        self.charged = np.zeros((batch, n_agents, len(KINDS)), dtype=bool)

    def reset(self, info: dict[str, np.ndarray], idx: np.ndarray | None = None) -> None:
        """Start the episodes of copies ``idx`` (all when ``None``) from their reset infos."""
        sel = slice(None) if idx is None else idx
        self.phi[sel] = potential(target_distance(info), self.spec)
        self.charged[sel] = False

    def step(self, info: dict[str, np.ndarray], terminated: np.ndarray, final: np.ndarray) -> np.ndarray:
        """The rewards ``(B, M)`` of a step of every copy (``final``: truncated by the horizon)."""
        rewards, self.phi, self.charged = training_rewards(self.spec, self.phi, self.charged, info,
                                                           terminated, final)
        return rewards


def with_safety_cost(info: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``info`` with the ``safety_cost`` ``(B, M)`` entry added (a new dict)."""
    return {**info, "safety_cost": safety_cost(info)}
