"""satenv.scoring: the one episode record and the one aggregate, and every reader of them agrees."""

from __future__ import annotations

import json

import numpy as np
import pytest

from satenv import scoring


def _rec(seed, policy="p", collisions=0, violations=0, success=True, error=None):
    rec = {"scenario": "s", "policy": policy, "seed": seed, "success": success, "collisions": collisions,
           "violations": violations, "rmse": 1.0, "delta_v": 1.0, "terminated": False, "error": error}
    return rec


EPISODES = [_rec(0, collisions=5, success=False),        # five flags: one collision episode
            _rec(1),
            _rec(2, collisions=1, violations=2, success=False, error="RuntimeError: crashed after it collided"),
            _rec(3, violations=1)]


def test_an_episode_with_any_collision_counts_once_errored_or_not():
    """The rule (scoring.COLLISION_EPISODE_RULE): 2 collision episodes here. Summing the flags
    would give 6; counting only episodes that ran to the end would give 1."""
    agg = scoring.aggregate(EPISODES)
    assert agg["collision_episodes"] == 2 and agg["violation_episodes"] == 2
    assert agg["episodes"] == 4 and agg["errors"] == 1 and agg["successes"] == 2


def test_the_board_the_headline_and_the_robustness_table_count_as_the_aggregate():
    from satenv.bench.scoreboard import report
    from satenv.bench.scoreboard.headline import _policy_stats

    want = scoring.aggregate(EPISODES)
    cell = report.aggregate(EPISODES)["s"]["p"]
    stats = _policy_stats(EPISODES)
    for got in (cell, stats):
        assert (got["collision_episodes"], got["violation_episodes"], got["errors"]) == \
            (want["collision_episodes"], want["violation_episodes"], want["errors"])
    perturbed = [{**r, "scenario": "s@nav-1m"} for r in EPISODES]
    board = report.Board(out=None, header={}, records=EPISODES + perturbed,
                         aggregates=report.aggregate(EPISODES + perturbed), ranking={})
    for pert in ("nominal", "nav-1m"):
        row = report.robustness(board)["s"]["p"][pert]
        assert (row["n"], row["successes"], row["collision_episodes"], row["violation_episodes"]) == (4, 2, 2, 2)


def test_the_reference_grid_counts_as_the_aggregate():
    from satenv.bench.learning.results import _point

    eps = [{**r, "episode_return": -1.0} for r in EPISODES if r["error"] is None]
    assert _point({"agent_steps": 10, "episodes": eps})[3] == scoring.aggregate(eps)["collision_episodes"] == 1


def test_one_record_for_a_filtered_episode_and_old_keys_read_through_the_map():
    import satenv
    from satenv.rollout import rollout
    from satenv.safety import shield

    class FullThrust:
        def reset(self, seed=None):
            pass

        def act(self, obs):
            return {a: -np.ones(3, dtype=np.float32) for a in obs}

    env = satenv.platoon_v0(preset="pereira2022", randomize=True, max_steps=100)
    traj = rollout(env, shield(FullThrust(), env), seed=0)
    rec = scoring.episode_record(traj, 0, len(env.possible_agents))
    assert rec["safety_agent_steps"] == traj.steps * len(env.possible_agents) and rec["safety_interventions"] > 0
    assert rec["interventions_per_agent_step"] == rec["safety_interventions"] / rec["safety_agent_steps"]
    assert rec["safety_mean_du"] > 0 and np.isfinite(rec["episode_return"])
    old = {"interventions": 3, "mean_du": 0.5, "infeasible_steps": 0, "steps": 4}
    assert scoring.upgrade_record(old) == {"safety_interventions": 3, "safety_mean_du": 0.5,
                                           "safety_infeasible": 0, "steps": 4}
    assert scoring.upgrade_record({"interventions": None, "mean_du": None, "steps": 4}) == {"steps": 4}


def test_the_published_board_log_reads_as_the_one_record():
    from pathlib import Path

    from satenv.bench.scoreboard.runner import read_episodes

    log = Path(__file__).resolve().parents[1] / "studies" / "published" / "episodes.jsonl"
    if not log.is_file():
        pytest.skip("no published board in this checkout")
    records = read_episodes(log)
    assert records and not any(set(scoring.LEGACY_KEYS) & set(r) for r in records)
    raw = [json.loads(line) for line in log.read_text().splitlines()[:50]]
    assert len(records) >= len(raw) > 0
