"""No warning spam on the main paths, and no silent garbage from the metrics.

PettingZoo's own API test, a scoreboard loading several policies trained on another setting,
numbers beyond the float range in the input checks, the shaping maps and a loaded policy: each
either says something once or says nothing (what it computes is checked downstream).
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

import satenv
from satenv import baselines, metrics, training
from satenv.errors import SatenvError
from satenv.rollout import rollout


def test_pettingzoo_api_test_passes_without_the_unknown_option_warning():
    from pettingzoo.test import parallel_api_test

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        parallel_api_test(satenv.make("platoon_v0", max_steps=20), num_cycles=5)
    assert not [w for w in caught if "reset option" in str(w.message)]


def test_an_unknown_reset_option_warns_once_per_env_and_key():
    env = satenv.make("platoon_v0", max_steps=5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(3):
            env.reset(seed=0, options={"initial_sate": None})
        env.reset(seed=0, options={"x0": None})
    hits = [str(w.message) for w in caught if "unknown reset option" in str(w.message)]
    assert len(hits) == 2 and "initial_sate" in hits[0] and "x0" in hits[1]


def test_a_setting_mismatch_warns_once_per_process_however_many_loads():
    """The quick board loads several policies trained with randomize=True on fixed scenarios:
    one warning, not one per policy."""
    from satenv.training import policy as tp

    tp._WARNED_SETTINGS.clear()
    env = satenv.make("formation_v0")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(3):
            training.load(training.POLICIES_DIR / "formation_position_dagger", env=env)
    assert len([w for w in caught if "differs from the policy's training" in str(w.message)]) == 1


def test_numbers_beyond_the_float_range_are_errors_not_runtime_warnings():
    from satenv.dynamics._checks import all_finite, first_nonfinite, numeric, real

    big = np.longdouble(10) ** 4000
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(SatenvError, match="finite"):
            numeric(np.array([big]), "x")
        with pytest.raises(SatenvError, match="finite"):
            real(big, "x")
        assert first_nonfinite({"s": np.array([[big]])}, ["a"]) == "s of a"
        assert not all_finite(np.array([np.inf, 1.0])) and not all_finite(np.array([np.nan, 1.0], np.float32))
        assert all_finite(np.ones(3), np.ones(2, np.float32))


@pytest.mark.parametrize("name", ["formation_collision_dagger_terminal", "platoon_pereira2022_ppo"])
def test_a_loaded_policy_flags_huge_observations_without_runtime_warnings(name):
    policy = training.load(training.POLICIES_DIR / name)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        for v in (1e30, 1e300, np.inf, np.nan):
            policy.reset()
            actions = policy.predict(np.full((3, *policy.obs_shape), v))
            assert np.isfinite(actions).all()      # NaN in: the flagged zero action
            assert policy.info["fallbacks"] == 3 or not np.isnan(v)


def test_reward_shaping_and_features_near_the_float_range_are_quiet():
    from satenv.training.shaping import ObsFeatures, RewardShaping

    shaping = RewardShaping.from_dict({"tracking": 1.0, "precision": 1.0, "proximity": 1.0,
                                       "anticipation": 1.0, "anticipation_speed": 1.0})
    state = np.zeros((2, 3, 13))
    state[:, 1, :] = 1e200
    info = {"tracking_error": state[..., :6], "min_separation": np.ones((2, 3)), "collision": np.zeros((2, 3)),
            "delta_v": np.zeros((2, 3)), "violations": np.zeros((2, 3)), "state": state}
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        shaping(np.zeros((2, 3)), info)
        ObsFeatures(50.0, 6, ())(np.full((3, 10), 1e307))


@pytest.fixture(scope="module")
def traj():
    env = satenv.make("platoon_v0", max_steps=6)
    return rollout(env, baselines.make("zero", env), seed=0)


@pytest.mark.parametrize("key", sorted(metrics.NONNEGATIVE_INFO))
def test_a_negative_magnitude_or_count_is_a_corrupt_trajectory(traj, key):
    a = np.asarray(traj.info[key]).astype(float).copy()
    a[2, 1] = -1e300
    bad = dataclasses.replace(traj, info={**traj.info, key: a})
    with pytest.raises(SatenvError, match=rf"{key}.*negative"):
        metrics.summary(bad)


@pytest.mark.parametrize(("key", "value"), [("tracking_error", 1e200), ("accel", 1e200), ("delta_v", 1e308)])
def test_overflowing_squares_or_sums_raise_naming_the_field(traj, key, value):
    a = np.asarray(traj.info[key]).astype(float).copy()
    a[1:] = value
    bad = dataclasses.replace(traj, info={**traj.info, key: a})
    with pytest.raises(SatenvError, match=key):
        metrics.summary(bad)


def test_an_empty_trajectory_is_an_error_not_nan(traj):
    empty = dataclasses.replace(traj, info={k: v[:0] for k, v in traj.info.items()}, t=traj.t[:0])
    for name in ("rmse", "foe", "delta_v_total", "summary"):
        with pytest.raises(SatenvError, match="no step"):
            getattr(metrics, name)(empty)
