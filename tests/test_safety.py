"""The safety filter (satenv.safety): minimal intervention, the backup, collisions, bad input.

Collisions and violations are read from the env's own infos (its physics and checks), never from
the filter's model.
"""

from __future__ import annotations

import numpy as np
import pytest

import satenv
from satenv import baselines, safety
from satenv.safety import SafetyConfig, SafetyError, SafetyFilter, filter_actions


def _random_episode(env, seed, filt=None, max_steps=None):
    """Random actions through the filter; returns (collisions, violations, interventions, steps)."""
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    m = len(env.possible_agents)
    collisions = violations = interventions = steps = 0
    while env.agents and (max_steps is None or steps < max_steps):
        a = rng.uniform(-1.0, 1.0, (m, env.core.action_dim))
        if filt is not None:
            a, rec = filt.filter(a)
            interventions += int(rec.intervened.sum())
        _, _, _, _, infos = env.step(dict(zip(env.possible_agents, a, strict=True)))
        collisions += any(i["collision"] for i in infos.values())
        violations += sum(int(i["violations"]) for i in infos.values())
        steps += 1
    return collisions, violations, interventions, steps


# ------------------------------------------------------------------------ minimal intervention
@pytest.mark.parametrize("env_id,kwargs", [("platoon_v0", {}), ("cluster_v0", {}),
                                           ("servicing_v0", {"randomize": True})])
def test_safe_proposal_passes_unchanged(env_id, kwargs):
    env = satenv.make(env_id, **kwargs)   # (the servicing preset starts on the keep-out sphere)
    env.reset(seed=0)
    filt = SafetyFilter(env)
    rng = np.random.default_rng(3)
    a = rng.uniform(-0.01, 0.01, (len(env.possible_agents), env.core.action_dim))  # nearly coasting
    out, rec = filt.filter(a)
    assert not rec.intervened.any()
    assert np.max(np.abs(out - a)) <= 1e-12
    assert np.array_equal(out, a) and rec.delta.max() == 0.0 and (rec.active == -1).all()


def test_unsafe_proposal_is_changed_minimally_and_stays_in_the_box():
    # two cluster satellites 250 m apart closing at 1.2 m/s: full thrust towards each other is unsafe
    env = _cluster_pair(gap=250.0, speed=0.6)
    filt = SafetyFilter(env)
    a = np.zeros((10, 3))
    a[0, 1], a[1, 1] = 1.0, -1.0                       # full thrust towards each other
    out, rec = filt.filter(a)
    assert rec.intervened[0, 0] and rec.intervened[0, 1] and not rec.intervened[0, 2:].any()
    assert np.array_equal(out[2:], a[2:])
    assert np.all(np.abs(out) <= 1.0 + 1e-12) and not rec.infeasible.any()
    assert set(rec.active_names[0, :2]) == {"separation"}
    # the change is the smallest in the QP's sense: pushing the two further apart is not needed
    assert out[0, 1] > -1.0 and out[1, 1] < 1.0
    assert rec.delta[0, 0] == pytest.approx(np.linalg.norm(out[0] - a[0]))


def test_shield_returns_the_policy_objects_when_safe():
    env = satenv.make("cluster_v0")
    obs, _ = env.reset(seed=0)
    zero = baselines.make("zero", env)
    shielded = baselines.make("shield", env, policy=zero)
    assert isinstance(shielded, baselines.Policy)
    proposed = zero.act(obs)
    acts = shielded.act(obs)
    assert all(np.array_equal(acts[a], proposed[a]) for a in acts)
    assert shielded.info["safety_interventions"] == 0 and shielded.info["safety_steps"] == 1
    assert satenv.safety.shield(zero, env).act(obs).keys() == proposed.keys()


# ------------------------------------------------------------------------ the backup
def _cluster_pair(gap, speed):
    """cluster_v0 (no disturbance) with satellites 1 and 2 ``gap`` m apart along y, closing at
    ``2 speed`` m/s; the others 900 m apart, far from the obstacle and the target spacecraft."""
    env = satenv.make("cluster_v0", disturbance="none")
    x0 = np.zeros((10, 6))
    x0[:, :3] = [[-3000.0, -4000.0 + 900.0 * k, 3000.0] for k in range(10)]
    x0[1, :3] = x0[0, :3] + [0.0, gap, 0.0]
    x0[0, 4], x0[1, 4] = speed, -speed
    env.reset(seed=0, options={"initial_state": x0})
    return env


def _closing_cluster():
    env = _cluster_pair(gap=230.0, speed=1.5)
    a = np.zeros((10, 3))
    a[0, 1], a[1, 1] = 1.0, -1.0
    return env, a


@pytest.mark.parametrize("fault", ["raise", "nan", "status", "wrong"])
def test_solver_failure_gives_the_backup_and_a_flag(monkeypatch, fault):
    env, a = _closing_cluster()

    def broken(u_ref, rows, lower, box):
        if fault == "raise":
            raise RuntimeError("injected")
        if fault == "nan":
            return np.full_like(u_ref, np.nan), 1
        if fault == "status":
            return u_ref, -1
        return u_ref, 1                                 # claims success, violates its rows

    monkeypatch.setattr(safety, "solve_qp", broken)
    out, rec = SafetyFilter(env).filter(a)
    assert rec.infeasible[0, 0] and rec.infeasible[0, 1] and rec.intervened[0, :2].all()
    assert np.all(np.isfinite(out)) and np.all(np.abs(out) <= 1.0)
    # maximum braking: each satellite thrusts away from the other (along -y / +y)
    assert out[0, 1] < 0.0 < out[1, 1]
    assert rec.active_names[0, 0] == "separation"


def test_infeasible_state_brakes_and_never_fails_open():
    env = _cluster_pair(gap=205.0, speed=3.0)             # cannot stop in 5 m at 0.04 m/s^2
    a = np.zeros((10, 3))
    a[0, 1], a[1, 1] = 1.0, -1.0
    out, rec = SafetyFilter(env).filter(a)
    assert rec.infeasible[0, :2].all()
    assert np.all(np.isfinite(out)) and out[0, 1] < 0.0 < out[1, 1]


# ------------------------------------------------------------------------ random policy: 0 collisions
@pytest.mark.parametrize("env_id,kwargs,seeds,max_steps", [
    ("platoon_v0", {}, (0, 1), None),
    ("platoon_v0", {"preset": "pereira2022"}, (0, 4), None),
    ("cluster_v0", {}, (0,), 150),
    ("servicing_v0", {}, (0,), 150),
    ("formation_v0", {"collision_distance": 5.0, "randomize": True}, (1,), 300),
])
def test_random_policy_under_the_filter_never_collides(env_id, kwargs, seeds, max_steps):
    env = satenv.make(env_id, **kwargs)
    filt = SafetyFilter(env)
    for seed in seeds:
        collisions, violations, interventions, steps = _random_episode(env, seed, filt, max_steps)
        assert collisions == 0, (env_id, seed)
        if env_id in ("platoon_v0", "servicing_v0"):   # their violations are all enforced rows
            assert violations == 0, (env_id, seed)
        assert steps > 0


def test_the_random_policy_collides_without_the_filter():
    """The tests above can fail: unfiltered, the same episodes collide."""
    assert _random_episode(satenv.make("platoon_v0"), 0)[0] > 0
    assert _random_episode(satenv.make("servicing_v0"), 0)[0] > 0
    assert _random_episode(satenv.make("cluster_v0"), 0)[0] > 0


def test_velocity_bound_40_holds_under_full_thrust():
    env = satenv.make("platoon_v0", max_steps=120)
    filt = SafetyFilter(env)
    env.reset(seed=0)
    worst = 0.0
    while env.agents:
        a, _ = filt.filter(np.tile([0.0, 1.0, 0.0], (4, 1)))
        _, _, _, _, infos = env.step(dict(zip(env.possible_agents, a, strict=True)))
        err = np.array([i["neighbourhood_error"][3:] for i in infos.values()])
        worst = max(worst, float((np.abs(err).max(axis=1) / (env.core.gains * 20.0)).max()))
    assert 0.9 < worst <= 1.0


# ------------------------------------------------------------------------ envs with the filter
def test_make_and_make_vec_with_safety_filter_report_and_penalise():
    env = satenv.make("platoon_v0", safety_filter=SafetyConfig(penalty=2.0))
    env.reset(seed=0)
    _, rewards, _, _, infos = env.step({a: np.array([0.0, 1.0, 0.0]) for a in env.agents})
    assert {"safety_intervened", "safety_delta", "safety_infeasible", "safety_active"} <= set(infos["follower_1"])
    assert isinstance(env, safety.wrapper.SafetyFilterWrapper) and type(env).metadata["name"] == "platoon_v0"
    assert type(env.unwrapped) is satenv.envs.platoon_v0.PlatoonEnv and env.core is env.unwrapped.core   # no class swap
    assert baselines.make("dmpc", env).env is env        # the baselines read type(env).metadata
    plain = satenv.make("platoon_v0")
    plain.reset(seed=0)
    _, ref, _, _, _ = plain.step({a: np.array([0.0, 1.0, 0.0]) for a in plain.agents})
    assert all(rewards[a] == pytest.approx(ref[a] - 2.0 * infos[a]["safety_delta"]) for a in ref)
    vec = satenv.make_vec("platoon_v0", 3, seed=0, safety_filter=True)
    vec.reset()
    _, r, _, _, info = vec.step(np.ones((3, 4, 3)))
    assert info["safety_intervened"].shape == (3, 4) and np.all(np.isfinite(r))
    with pytest.raises(TypeError, match="safety_filter must be"):
        satenv.make("platoon_v0", safety_filter="yes")


@pytest.mark.parametrize("env_id", ["platoon_v0", "servicing_v0"])
def test_filtered_env_passes_the_pettingzoo_api_test(env_id):
    from pettingzoo.test import parallel_api_test

    parallel_api_test(satenv.make(env_id, safety_filter=True, max_steps=20), num_cycles=20)


# ------------------------------------------------------------------------ bad input
def test_bad_input_names_the_field():
    env = satenv.make("platoon_v0")
    env.reset(seed=0)
    filt = SafetyFilter(env)
    x, t = env.core.x, np.zeros(1)
    good = np.zeros((1, 4, 3))
    with pytest.raises(SafetyError, match="actions has non-finite"):
        filter_actions(filt.model, filt.config, x, t, np.full((1, 4, 3), np.nan))
    with pytest.raises(SafetyError, match="state has non-finite"):
        filter_actions(filt.model, filt.config, np.full_like(x, np.nan), t, good)
    with pytest.raises(SafetyError, match=r"actions must have shape \(copies, 4, 3\)"):
        filt.filter(np.zeros((1, 4, 2)))
    with pytest.raises(SafetyError, match="state must have shape"):
        filter_actions(filt.model, filt.config, x[:, :3], t, good)
    with pytest.raises(TypeError, match="actions must be a real array"):
        filt.filter("left")
    with pytest.raises(SafetyError, match=r"unknown option\(s\) \['margins'\]"):
        SafetyFilter(env, margins=0.1)
    for name, bad in (("margin", 0.0), ("margin", -0.1), ("los_margin", 0.0), ("velocity_margin", 1.0),
                      ("gamma", 0.0), ("gamma", 1.5), ("penalty", -1.0), ("margin", np.inf)):
        with pytest.raises(SafetyError, match=f"SafetyConfig.{name} must be finite"):
            SafetyConfig(**{name: bad})
    with pytest.raises(TypeError, match="SafetyConfig.margin must be a real number"):
        SafetyConfig(margin=True)
    with pytest.raises(TypeError, match="needs a satenv env"):
        SafetyFilter(object())
    with pytest.raises(baselines.BaselineError, match="policy is required"):
        baselines.make("shield", env)
    out, _ = filt.filter(good)                          # a rejected call leaves the filter usable
    assert np.array_equal(out, good)


# ------------------------------------------------------------------------ scoreboard
def test_scoreboard_ranks_a_policy_beside_its_shielded_twin(tmp_path):
    from satenv.bench.scoreboard import run_scoreboard
    from satenv.bench.scoreboard.cli import with_shield

    assert with_shield("random,dmpc", False) == "random,dmpc,random+shield,dmpc+shield"
    board = run_scoreboard(tmp_path, scenarios="platoon-chain-cw", policies=with_shield("random", False),
                           seeds="0", plots=False, progress=False)
    agg = board.aggregates["platoon-chain-cw"]
    assert set(agg) == {"random", "random+shield"}
    assert agg["random+shield"]["safety_interventions"]["n"] == 1 and agg["random"]["safety_interventions"]["n"] == 0
    assert agg["random+shield"]["collisions"]["mean"] == 0
    assert "interventions" in board.markdown and "mean ‖Δu‖" in board.markdown


def test_torchrl_env_with_safety_filter():
    pytest.importorskip("torchrl")
    from torchrl.envs.utils import check_env_specs

    from satenv.torchrl import make_env

    env = make_env("platoon_v0", 2, seed=0, safety_filter=True)
    check_env_specs(env)
    td = env.rollout(20)
    assert td["next", "agents", "safety_intervened"].shape == (2, 20, 4, 1)
    assert "safety_delta" not in make_env("platoon_v0", 2, seed=0).observation_spec["agents"].keys()
