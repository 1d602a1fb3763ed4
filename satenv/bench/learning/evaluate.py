"""One evaluation of a policy on a run's test seeds: episode records and the curve point.

Each episode is :func:`satenv.scoring.episode_record` of a :func:`satenv.rollout.rollout` (the one
record the board logs too, ``episode_return`` included); only the fields the results use are kept
(:data:`EPISODE_FIELDS`).
A run trained with the filter is evaluated as trained: behind :func:`satenv.safety.shield` (the
filter's default options), which also counts its interventions.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from satenv import scoring

__all__ = ["EPISODE_FIELDS", "evaluate_policy"]

EPISODE_FIELDS = ("seed", "success", "collisions", "violations", "terminated", "rmse", "delta_v",
                  "final_error_m", "steps", "min_separation_m", "compute_ms_per_agent", "episode_return",
                  "failure_mode", *scoring.SAFETY_COUNTS, "safety_agent_steps")
"""What a logged episode keeps."""


def _clean(value: Any) -> Any:
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(float(value)) else None
    return value


def evaluate_policy(make_env: Callable[[], Any], make_policy: Callable[[Any], Any], seeds: Iterable[int],
                    filtered: bool = False) -> list[dict[str, Any]]:
    """The episode records of ``make_policy(env)`` (behind the filter when ``filtered``) on ``seeds``."""
    from satenv.rollout import rollout
    from satenv.safety import shield

    env = make_env()
    policy = make_policy(env)
    if filtered:
        policy = shield(policy, env)
    out = []
    try:
        for seed in seeds:
            traj = rollout(env, policy, seed=int(seed))
            rec = scoring.episode_record(traj, int(seed), len(env.possible_agents))
            out.append({k: _clean(rec[k]) for k in EPISODE_FIELDS if k in rec})
    finally:
        env.close()
    return out
