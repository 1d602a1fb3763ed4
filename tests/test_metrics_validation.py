"""``satenv.metrics`` validates its input (issue 29 item 3).

A recorded trajectory is corrupted at random (arrays emptied, truncated, reshaped, NaN/inf or
huge entries, wrong dtypes, bad ``dt``/``t``/tolerances, non-bool flags): every metric either
raises :class:`satenv.errors.SatenvError` (a ``ValueError``/``TypeError``) naming the field, or
returns finite values (the one documented ``nan``: :func:`time_to_converge` of an agent that did
not converge). The uncorrupted trajectory gives the reference values (checked by hand below).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import satenv
from satenv import baselines, metrics
from satenv.errors import SatenvError
from satenv.rollout import rollout

METRICS = ("rmse", "rmsee", "foe", "final_position_error", "delta_v_total", "min_separation", "collisions",
           "violations", "safety_cost", "time_to_converge", "success", "summary")
KEYS = ("tracking_error", "accel", "delta_v", "min_separation", "collision", "violations", "cost")


@pytest.fixture(scope="module")
def traj():
    env = satenv.platoon_v0(max_steps=6)
    return rollout(env, baselines.make("zero", env), seed=0)


def test_reference_values_by_hand(traj):
    e = traj.info["tracking_error"]
    assert np.allclose(metrics.rmse(traj), np.sqrt(np.mean(np.sum(e[:-1] ** 2, axis=-1), axis=0)))
    assert np.allclose(metrics.foe(traj), np.linalg.norm(e[-1], axis=-1))
    assert metrics.rmsee(traj).tolist() == [0.0] * 4          # zero thrust
    assert np.isfinite(list(v for v in metrics.summary(traj).values() if isinstance(v, float)
                            and v == v)).all()


@pytest.mark.parametrize(("change", "field"), [
    ({"info": "empty"}, "no step"),
    ({"info": "reset_only"}, "no step"),
    ({"dt": -0.1}, "trajectory.dt"),
    ({"dt": 0.0}, "trajectory.dt"),
    ({"collision_voids_success": "no"}, "collision_voids_success must be a bool"),
    ({"success_tol": float("nan")}, "success_tol"),
    ({"success_tol": True}, "success_tol"),
])
def test_the_audit_cases_raise_naming_the_field(traj, change, field):
    if change.get("info") == "empty":
        bad = dataclasses.replace(traj, info={k: v[:0] for k, v in traj.info.items()}, t=traj.t[:0])
    elif change.get("info") == "reset_only":
        bad = dataclasses.replace(traj, info={k: v[:1] for k, v in traj.info.items()}, t=traj.t[:1],
                                  actions=traj.actions[:0])
    else:
        bad = dataclasses.replace(traj, **change)
    with pytest.raises(SatenvError, match=field):
        metrics.summary(bad)


def test_one_nan_in_tracking_error_is_an_error_not_a_nan_rmse(traj):
    info = {k: v.copy() for k, v in traj.info.items()}
    info["tracking_error"][2, 1, 4] = np.nan
    bad = dataclasses.replace(traj, info=info)
    for name in ("rmse", "foe", "summary"):
        with pytest.raises(SatenvError, match=r"tracking_error.*NaN/inf.*\(2, 1, 4\)"):
            getattr(metrics, name)(bad)


def test_tol_argument_is_checked(traj):
    for bad in (0, -1.0, float("inf"), "1", True, None):
        if bad is None:
            continue
        with pytest.raises(SatenvError, match="tol"):
            metrics.success(traj, tol=bad)


def _corrupt(traj, draw) -> tuple[object, str]:
    kind = draw(st.sampled_from(("array", "dt", "t", "tol", "voids", "missing", "agents", "compute",
                                 "fallbacks")))
    if kind == "array":
        key = draw(st.sampled_from(KEYS))
        a = np.asarray(traj.info[key])
        how = draw(st.sampled_from(("nan", "inf", "huge", "empty", "one", "ndim", "complex", "object",
                                    "str", "bool", "rows", "cols", "list")))
        if how in ("nan", "inf", "huge"):
            a = a.astype(float).copy()
            a.flat[draw(st.integers(0, a.size - 1))] = {"nan": np.nan, "inf": -np.inf, "huge": 1e300}[how]
        else:
            a = {"empty": a[:0], "one": a[:1], "ndim": a.reshape(-1), "complex": a + 1j,
                 "object": a.astype(object), "str": a.astype(str), "bool": a.astype(bool),
                 "rows": a[:-1], "cols": a[:, :-1], "list": a.tolist()}[how]
        return dataclasses.replace(traj, info={**traj.info, key: a}), key
    if kind == "dt":
        return dataclasses.replace(traj, dt=draw(st.sampled_from([0.0, -1.0, np.nan, np.inf, "0.1", None]))), "dt"
    if kind == "t":
        t = traj.t.copy()
        t[draw(st.integers(0, t.size - 1))] = draw(st.sampled_from([np.nan, -1e9, np.inf]))
        return dataclasses.replace(traj, t=t), "t"
    if kind == "tol":
        return dataclasses.replace(traj, success_tol=draw(st.sampled_from([0, -1, np.nan, "x", True, 1e400]))), "tol"
    if kind == "voids":
        return dataclasses.replace(traj, collision_voids_success=draw(st.sampled_from(["no", 1, None, 0.0]))), "voids"
    if kind == "missing":
        key = draw(st.sampled_from(KEYS))
        return dataclasses.replace(traj, info={k: v for k, v in traj.info.items() if k != key}), key
    if kind == "agents":
        return dataclasses.replace(traj, agents=traj.agents[:-1]), "agents"
    if kind == "compute":
        return dataclasses.replace(traj, compute_time=np.array([np.nan])), "compute_time"
    bad = draw(st.sampled_from([-1, 1.5, "2", True]))
    return dataclasses.replace(traj, policy_info={"fallbacks": bad}), "fallbacks"


@settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))
@given(data=st.data())
def test_corrupted_trajectories_raise_naming_the_field_or_give_finite_values(traj, data):
    bad, field = _corrupt(traj, data.draw)
    name = data.draw(st.sampled_from(METRICS))
    try:
        out = getattr(metrics, name)(bad)
    except SatenvError as exc:
        assert isinstance(exc, ValueError | TypeError)
        assert field in str(exc), (field, str(exc))
        return
    values = out.values() if isinstance(out, dict) else [out]
    for key, v in zip(out if isinstance(out, dict) else [name], values, strict=True):
        if key in ("time_to_converge", "time_to_converge_s"):
            continue  # documented: nan for an agent that did not converge
        if isinstance(v, np.ndarray | float | int):
            assert np.isfinite(np.asarray(v, dtype=float)).all(), (name, key, field)
