"""The task registry (satenv.tasks), the scoring module (satenv.scoring) and the perturbations."""

from __future__ import annotations

import math

import numpy as np
import pytest

import satenv
from satenv import perturbations, scoring, tasks
from satenv.errors import SatenvError


def test_splits_are_disjoint_and_the_check_can_fail():
    bands = list(tasks.SEED_SPLITS.values())
    for i, a in enumerate(bands):
        for b in bands[i + 1:]:
            assert not set(a) & set(b)
    tasks.check_splits()
    with pytest.raises(SatenvError, match="overlap"):
        tasks.check_splits({"train": range(0, 10), "test": range(5, 20)})
    with pytest.raises(SatenvError, match="non-empty"):
        tasks.check_splits({"train": range(3, 3)})


@pytest.mark.parametrize("name", tasks.names())
def test_every_task_builds_its_env_and_its_seeds_are_in_their_split(name):
    task = tasks.get(name)
    for split in tasks.SPLITS:
        seeds = task.seeds(split, 3)
        assert all(task.split_of(s) == split for s in seeds)
    test = set(task.seeds("test"))
    assert not test & set(task.seeds("train", 1000)) and not test & set(task.seeds("validation", 1000))
    if not task.randomized:
        assert task.seeds("test") == (tasks.SEED_SPLITS["test"].start,)   # one episode: no interval


@pytest.mark.parametrize("name", [n for n in tasks.names() if tasks.get(n).randomized
                                  and "swarm" not in n])
def test_a_randomised_task_gives_different_starts_for_different_test_seeds(name):
    task = tasks.get(name)
    env = task.make_env()
    a, b = task.seeds("test", 2)
    env.reset(seed=a)
    sa = env.state()
    env.reset(seed=b)
    assert not np.allclose(sa, env.state())
    env.reset(seed=a)
    np.testing.assert_array_equal(sa, env.state())
    assert env.metadata["task"] == name and env.metadata["cost_budget"] == task.cost_budget


def test_systems_have_a_randomised_training_task_and_a_deterministic_paper_task():
    assert len(tasks.SYSTEMS) == 6
    for system in tasks.SYSTEMS.values():
        train, paper = tasks.training_task(system.name), tasks.paper_task(system.name)
        assert train.randomized and not paper.randomized
        assert train.env_id == paper.env_id and train.controller == paper.controller == system.controller
    assert tasks.get("cluster-case1-random").expert == "replanning_tube_rdmpc"


def test_the_servicing_training_task_starts_outside_the_keep_out_sphere():
    """RL-usable: the paper start touches the keep-out sphere, the training task's starts do not."""
    task = tasks.training_task("servicing-pereira2022")
    env = task.make_env()
    for seed in task.seeds("train", 20):
        env.reset(seed=seed)
        _, _, terms, _, infos = env.step({a: np.zeros(6, np.float32) for a in env.agents})
        assert not any(terms.values()) and all(i["min_separation"] > 0 for i in infos.values())


def test_cost_budgets():
    assert tasks.get("cluster-case1-random").cost_budget == 0.0
    assert tasks.get("platoon-PLF-cw").cost_budget is None     # the paper's formation is in contact


def test_unknown_names_are_clear_errors():
    for call, arg in ((tasks.get, "nope"), (tasks.system, "nope"), (perturbations.get, "nope")):
        with pytest.raises(SatenvError, match="nope"):
            call(arg)
    with pytest.raises(SatenvError, match="split"):
        tasks.get("cluster-case1").seeds("holdout")
    with pytest.raises(SatenvError, match="seeds"):
        tasks.parse_seeds("3-1")
    assert tasks.parse_seeds("0-2,7") == (0, 1, 2, 7) and tasks.show_seeds((4, 5, 6)) == "4-6"


# ------------------------------------------------------------------ scoring
def _rec(seed, success=True, collisions=0, violations=0, rmse=1.0, delta_v=2.0, terminated=False):
    return {"seed": seed, "success": success, "collisions": collisions, "violations": violations, "rmse": rmse,
            "delta_v": delta_v, "terminated": terminated, "min_separation_m": 5.0, "final_error_m": 0.1}


def test_aggregate_counts_episodes_and_leaves_errors_out_of_the_means():
    eps = [_rec(0), _rec(1, success=False, collisions=3), _rec(2, violations=1, rmse=3.0),
           {"seed": 3, "error": "crashed"}]
    agg = scoring.aggregate(eps)
    assert (agg["episodes"], agg["errors"], agg["collision_episodes"], agg["violation_episodes"]) == (4, 1, 1, 1)
    assert agg["success_rate"] == 0.5 and agg["safe_success_rate"] == 0.25
    assert math.isclose(agg["rmse"], 5 / 3) and agg["success_ci95"][0] < 0.5 < agg["success_ci95"][1]
    with pytest.raises(SatenvError):
        scoring.aggregate([])


def test_targets_use_the_named_thresholds():
    agg = {"success_rate": 0.95, "collision_episodes": 0, "violation_episodes": 0}
    ratios = {"rmse_ratio": 1.2, "delta_v_ratio": scoring.RATIO_LIMIT}
    assert all(scoring.targets(agg, {"success_rate": 1.0}, ratios).values())
    assert not scoring.targets({**agg, "success_rate": 0.94}, {"success_rate": 1.0}, ratios)["success"]
    assert not scoring.targets(agg, None, {**ratios, "rmse_ratio": 1.51})["rmse"]
    assert not scoring.targets(agg, None, {})["delta_v"]           # no matched episode: not met


def test_the_ranking_puts_safety_before_tracking():
    """Equal success: the policy without collisions ranks first even with a worse RMSE; then
    violations; success still comes first."""
    safe = scoring.rank_key(1.0, 0, 0, 2.0, 1.0)
    unsafe = scoring.rank_key(1.0, 0, 6, 1.0, 1.0)
    colliding = scoring.rank_key(1.0, 1, 0, 0.5, 0.5)
    worse = scoring.rank_key(0.9, 0, 0, 0.1, 0.1)
    assert sorted([worse, colliding, unsafe, safe]) == [safe, unsafe, colliding, worse]


# ------------------------------------------------------------------ perturbations
def test_navigation_error_is_what_the_policy_and_state_read_and_the_truth_is_scored():
    task = tasks.get("platoon-pereira2022-random")
    nominal, noisy = task.make_env(), perturbations.make_env(task, "nav-1m")
    seed = task.seeds("test", 1)[0]
    o0, _ = nominal.reset(seed=seed)
    o1, _ = noisy.reset(seed=seed)
    assert not np.allclose(nominal.state(), noisy.state())
    assert not np.allclose(o0["follower_1"], o1["follower_1"])
    act = {a: np.full(3, 0.3, np.float32) for a in nominal.agents}
    _, _, _, _, i0 = nominal.step(act)
    _, _, _, _, i1 = noisy.step(act)
    for a in nominal.possible_agents:     # the truth flew the same: the estimate never reached physics
        np.testing.assert_allclose(i0[a]["tracking_error"], i1[a]["tracking_error"], rtol=1e-12, atol=1e-12)


def test_thrust_and_truth_perturbations_change_the_physics_not_the_nominal_model():
    task = tasks.get("cluster-case1-random")
    seed = task.seeds("test", 1)[0]
    act = None
    errors = {}
    for name in (None, "thrust-80", "disturbance-x2"):
        env = perturbations.make_env(task, name)
        env.reset(seed=seed)
        act = {a: np.ones(3, np.float32) for a in env.agents}
        for _ in range(3):
            _, _, _, _, info = env.step(act)
        errors[name] = np.array([info[a]["tracking_error"][:3] for a in env.possible_agents])
        assert env.scenario.disturbance_force == task.make_env().scenario.disturbance_force
    assert not np.allclose(errors[None], errors["thrust-80"])
    assert not np.allclose(errors[None], errors["disturbance-x2"])


@pytest.mark.parametrize("name", tasks.names())
def test_every_registered_perturbation_builds(name):
    task = tasks.get(name)
    assert set(task.perturbations) <= set(perturbations.PERTURBATIONS)
    for p in task.perturbations:
        env = perturbations.make_env(task, p)
        env.reset(seed=task.seeds("test", 1)[0])
        assert isinstance(env.state(), np.ndarray)


def test_a_baseline_runs_on_a_perturbed_env():
    from satenv import baselines
    from satenv.rollout import rollout

    task = tasks.get("platoon-pereira2022-random")
    env = perturbations.make_env(task, "nav-0.1m", max_steps=20)
    rec = scoring.episode_record(rollout(env, baselines.make("dmpc", env), seed=task.seeds("test", 1)[0]),
                                 task.seeds("test", 1)[0], len(env.possible_agents))
    assert rec["steps"] == 20 and np.isfinite(rec["rmse"])
    assert isinstance(satenv.make("platoon_v0"), object)
