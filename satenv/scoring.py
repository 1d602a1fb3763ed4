"""How an evaluation is scored, one home for the training evaluation, the held-out recipe, the
policy card and the scoreboard.

* **Episode record** (:func:`episode_record`, the one record of the board, the reference grid,
  ``satenv.bench.safety_alone`` and the training evaluation): :func:`satenv.metrics.summary` of a
  trajectory, plus ``seed``, ``compute_ms_per_agent``, ``episode_return`` (the env's reward summed
  over the episode, mean over agents) and, for a policy behind the safety filter, its counts
  ``safety_interventions`` and ``safety_infeasible`` (agent-steps), ``safety_steps`` (decisions
  filtered, as :class:`satenv.safety.Shield` counts them), ``safety_agent_steps`` (decisions x
  agents), ``interventions_per_agent_step`` (their ratio) and ``safety_mean_du`` (mean ``|du|`` of
  an intervention; ``None`` without any), ``failure_mode`` (:func:`failure_mode`; ``None`` for a
  success). Records written under older key names are read through
  :func:`upgrade_record` (:data:`LEGACY_KEYS`).
* **Aggregate** (:func:`aggregate`) of a list of records, keys:

  ================================  =============================================================
  ``episodes``, ``successes``       number of episodes, of successful ones
  ``success_rate``                  share of successful episodes (the scenario's rule, ``metrics.success``)
  ``success_ci95``                  95 % Wilson interval of ``success_rate`` (``None`` on one episode)
  ``collision_episodes``            episodes with at least one collision flag, each counted once
                                    however many flags it raised, an episode that crashed after
                                    colliding included (:data:`COLLISION_EPISODE_RULE`)
  ``violation_episodes``            episodes with at least one hard-constraint violation
  ``safe_success_rate``             share reached with no collision and no violation
  ``violations``                    mean violations per episode
  ``terminated``                    episodes that ended early (collision, left the region)
  ``rmse``, ``delta_v``, ...        means over episodes (``final_error_m``, ``time_to_converge_s``
                                    over the episodes that converged, ``compute_ms_per_agent``)
  ``min_separation_m``              smallest separation over every episode
  ``interventions_per_agent_step``  filter interventions / agent-steps (filtered policies only)
  ================================  =============================================================

* **Ratio rule**: :func:`satenv.metrics.matched_ratios` (ratios of the means on matched, completed
  episodes), re-exported here.
* **Target rule** (:func:`targets`) with named thresholds, and the **safety-first ranking**
  (:func:`rank_key`): success rate, then collision episodes, then violation episodes, then RMSE,
  then delta-v.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from satenv.errors import SatenvError
from satenv.metrics import matched_ratios, summary

__all__ = ["COLLISION_EPISODE_RULE", "DECISION_MS_PER_AGENT_LIMIT", "FAILURE_MODES", "LEGACY_KEYS", "RATIO_LIMIT",
           "SAFETY_COUNTS", "SUCCESS_MARGIN", "SUCCESS_MIN", "aggregate", "collision_episodes", "episode_record",
           "failure_mode", "matched_ratios",
           "rank_key", "run_episodes", "targets", "upgrade_record", "wilson"]

SUCCESS_MIN = 0.9
"""A learned policy's success rate must be at least this."""
SUCCESS_MARGIN = 0.05
"""... and at least the controller's success rate minus this margin (5 points)."""
RATIO_LIMIT = 1.5
"""RMSE and delta-v of a learned policy: at most this multiple of the controller's (matched episodes)."""
DECISION_MS_PER_AGENT_LIMIT = 1.0
"""A learned policy's decision time per agent [ms]."""

SAFETY_COUNTS = ("safety_interventions", "safety_infeasible", "safety_steps")
"""The safety filter's counts an episode record copies from the policy's ``info``."""

LEGACY_KEYS = {"interventions": "safety_interventions", "infeasible_steps": "safety_infeasible",
               "mean_du": "safety_mean_du"}
"""Older name -> name of the one record: the scoreboard's logs written before the record was one
(``studies/published/episodes.jsonl``) are read through :func:`upgrade_record`."""

COLLISION_EPISODE_RULE = "an episode with at least one collision flag counts once, errored or not"
"""How :func:`aggregate` counts collision (and violation) episodes, in words."""


FAILURE_MODES = ("collision", "violation", "left_region", "timeout")
"""Why an episode failed, the first that applies: a collision, a hard-bound violation, it ended
early without either (an agent left the allowed region), or it ran to the horizon outside the
tolerance (timeout)."""


def failure_mode(rec: Mapping[str, Any]) -> str | None:
    """The :data:`FAILURE_MODES` entry of an episode record (``None`` for a success)."""
    if rec.get("success"):
        return None
    if rec.get("collisions"):
        return "collision"
    if rec.get("violations"):
        return "violation"
    return "left_region" if rec.get("terminated") else "timeout"


def episode_record(traj: Any, seed: int, n_agents: int) -> dict[str, Any]:
    """The one episode record (module docstring): ``metrics.summary(traj)`` with ``seed``,
    ``compute_ms_per_agent``, ``episode_return`` and the filter's counts from the policy's ``info``
    (``traj.policy_info``) when it has them."""
    rec = summary(traj)
    info = traj.policy_info or {}
    agents = max(1, int(n_agents))
    rec["seed"] = int(seed)
    rec["compute_ms_per_agent"] = rec["compute_ms_per_decision"] / agents
    rec["episode_return"] = float(np.mean(np.sum(traj.rewards, axis=0))) if traj.steps else 0.0
    rec["failure_mode"] = failure_mode(rec)
    if "safety_steps" not in info:
        return rec
    for key in SAFETY_COUNTS:
        rec[key] = int(info[key])
    # the filter counts decisions; an intervention is one agent's action
    rec["safety_agent_steps"] = rec["safety_steps"] * agents
    n = rec["safety_interventions"]
    rec["interventions_per_agent_step"] = n / rec["safety_agent_steps"] if rec["safety_agent_steps"] else None
    rec["safety_mean_du"] = float(info["safety_delta"]) / n if n and "safety_delta" in info else None
    return rec


def upgrade_record(rec: Mapping[str, Any]) -> dict[str, Any]:
    """``rec`` with its :data:`LEGACY_KEYS` renamed; a legacy key holding ``None`` (a policy
    without the filter) is dropped, as the one record leaves the filter's keys out there."""
    out = {}
    for key, value in rec.items():
        new = LEGACY_KEYS.get(key)
        if new is None:
            out[key] = value
        elif value is not None and new not in rec:
            out[new] = value
    return out


def collision_episodes(episodes: Iterable[Mapping[str, Any]], key: str = "collisions") -> int:
    """Episodes whose ``key`` count is non-zero (:data:`COLLISION_EPISODE_RULE`; ``key="violations"``:
    violation episodes)."""
    return sum(bool(e.get(key)) for e in episodes)


def run_episodes(env: Any, policy: Any, seeds: Iterable[int]) -> list[dict[str, Any]]:
    """Roll ``policy`` out on ``env`` once per seed (``satenv.rollout.rollout``) and return the
    :func:`episode_record` of each episode."""
    from satenv.rollout import rollout

    out = []
    for seed in seeds:
        traj = rollout(env, policy, seed=int(seed))
        out.append(episode_record(traj, int(seed), len(env.possible_agents)))
    return out


def wilson(successes: int, n: int) -> tuple[float, float, float]:
    """Success rate and its 95 % Wilson score interval (``scipy.stats.binomtest``); NaNs for n = 0."""
    from scipy import stats

    if n == 0:
        return math.nan, math.nan, math.nan
    ci = stats.binomtest(int(successes), int(n)).proportion_ci(confidence_level=0.95, method="wilson")
    return successes / n, float(ci.low), float(ci.high)


def _mean(eps: list[dict[str, Any]], key: str) -> float | None:
    vals = [float(e[key]) for e in eps if e.get(key) is not None and math.isfinite(float(e[key]))]
    return float(np.mean(vals)) if vals else None


def aggregate(episodes: Iterable[dict[str, Any]]) -> dict[str, Any]:
    """The aggregate of episode records (keys in the module docstring). Records with an ``error``
    (an episode that crashed) count as failures and are left out of the means; collision and
    violation episodes count every record (:data:`COLLISION_EPISODE_RULE`)."""
    eps = list(episodes)
    if not eps:
        raise SatenvError("aggregate() needs at least one episode record, got none")
    ok = [e for e in eps if e.get("error") is None]
    wins = sum(bool(e.get("success")) for e in eps)
    rate, lo, hi = wilson(wins, len(eps))
    safe = sum(bool(e.get("success")) and not e.get("collisions") and not e.get("violations") for e in eps)
    out: dict[str, Any] = {
        "episodes": len(eps), "errors": len(eps) - len(ok), "successes": wins, "success_rate": rate,
        "success_ci95": [lo, hi] if len(eps) > 1 else None,
        "collision_episodes": collision_episodes(eps),
        "violation_episodes": collision_episodes(eps, "violations"),
        "safe_success_rate": safe / len(eps),
        "terminated": sum(bool(e.get("terminated")) for e in ok),
        "violations": _mean(ok, "violations"),
    }
    for key in ("rmse", "rmsee", "delta_v", "final_error_m", "time_to_converge_s", "compute_ms_per_agent",
                "compute_ms_per_decision", "steps", "episode_return"):
        out[key] = _mean(ok, key)
    seps = [e["min_separation_m"] for e in ok if e.get("min_separation_m") is not None]
    out["min_separation_m"] = float(min(seps)) if seps else None
    if any("safety_interventions" in e for e in ok):
        for key in SAFETY_COUNTS:
            out[key] = int(sum(e.get(key, 0) for e in ok))
        agent_steps = int(sum(e.get("safety_agent_steps", e.get("safety_steps", 0)) for e in ok))
        out["safety_agent_steps"] = agent_steps
        out["interventions_per_agent_step"] = out["safety_interventions"] / agent_steps if agent_steps else None
    return out


def targets(agg: Mapping[str, Any], ref: Mapping[str, Any] | None, ratios: Mapping[str, Any]) -> dict[str, bool]:
    """A learned policy's targets against its controller (``True`` = met): success >= :data:`SUCCESS_MIN`
    and >= the controller's minus :data:`SUCCESS_MARGIN`; no collision episode; no violation
    episode; RMSE and delta-v ratios (matched episodes) <= :data:`RATIO_LIMIT`; a decision <=
    :data:`DECISION_MS_PER_AGENT_LIMIT` ms per agent (when measured)."""
    ref_rate = None if ref is None else ref.get("success_rate")
    out = {"success": agg["success_rate"] >= SUCCESS_MIN
           and (ref_rate is None or agg["success_rate"] >= ref_rate - SUCCESS_MARGIN - 1e-12),
           "no_collisions": agg["collision_episodes"] == 0,
           "no_violations": agg.get("violation_episodes", 0) == 0,
           "rmse": (ratios.get("rmse_ratio") if ratios.get("rmse_ratio") is not None else math.inf) <= RATIO_LIMIT,
           "delta_v": (ratios.get("delta_v_ratio") if ratios.get("delta_v_ratio") is not None else math.inf)
           <= RATIO_LIMIT}
    if agg.get("compute_ms_per_agent") is not None:
        out["decision_time"] = agg["compute_ms_per_agent"] <= DECISION_MS_PER_AGENT_LIMIT
    return out


def rank_key(success_rate: float | None, collision_episodes: float | None, violation_episodes: float | None,
             rmse: float | None, delta_v: float | None) -> tuple[float, ...]:
    """The safety-first ranking key (sort ascending: best first): success rate (higher first), then
    collision episodes, then violation episodes, then RMSE, then delta-v (fewer / lower first); a
    missing value ranks last on its criterion."""
    def v(x: float | None, sign: float = 1.0) -> float:
        return math.inf if x is None or (isinstance(x, float) and math.isnan(x)) else sign * float(x)

    return (v(success_rate, -1.0), v(collision_episodes), v(violation_episodes), v(rmse), v(delta_v))
