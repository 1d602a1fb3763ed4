"""The servicing core's compiled paths (issue 25) against the numpy reference: the attitude
reference kernel (eq. 43-49, quaternion and pointing errors) and the whole core.

Tolerance 1e-12: the kernel evaluates the reference's formulas in component arithmetic (rotation
matrix from its closed-form entries, ``J_f^-1`` as an inverse), so the two differ by rounding.
"""

from __future__ import annotations

import numpy as np
import pytest
from step_results import assert_same_step

from satenv.dynamics import RelativeModel
from satenv.dynamics.attitude import pointing_error, quat_error
from satenv.envs.servicing_v0 import POINTING_MIN_SINE, ServicingCore, attitude_reference
from satenv.scenarios.servicing import resolve_scenario

pytest.importorskip("numba")
from satenv.envs._servicing_kernel import attitude_features  # noqa: E402

TOL = 1e-12


def _states(rng, shape):
    x = np.empty((*shape, 13))
    x[..., :3] = rng.normal(size=(*shape, 3)) * 20.0
    x[..., 3:6] = rng.normal(size=(*shape, 3)) * 0.1
    q = rng.normal(size=(*shape, 4))
    x[..., 6:10] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x[..., 10:] = rng.normal(size=(*shape, 3)) * 0.05
    return x


def test_attitude_features_match_the_numpy_functions():
    sc = resolve_scenario("pereira2022")
    rng = np.random.default_rng(0)
    x = _states(rng, (64, 4))
    ref = np.asarray(sc.pointing_reference)
    x[0, :, :3] = ref * np.array([[5.0], [-7.0], [11.0], [0.3]])   # k_d parallel to a: the fallback axis
    out = np.empty((64, 4, 4)), np.empty((64, 4, 3)), np.empty((64, 4, 4)), np.empty((64, 4))
    bad = attitude_features(x, np.asarray(sc.pointing_target, dtype=float), ref, sc.mean_motion,
                            POINTING_MIN_SINE, *out)
    assert bad == 0
    p, v, q = x[..., :3], x[..., 3:6], x[..., 6:10]
    r_d, q_d, w_d = attitude_reference(sc, p, v, q)
    expected = (q_d, w_d, quat_error(q, q_d), pointing_error(q, p, sc.pointing_target))
    for got, want in zip(out, expected, strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=TOL)
    # every branch of Shepperd's method is exercised
    d = np.stack([np.trace(r_d, axis1=-2, axis2=-1), r_d[..., 0, 0], r_d[..., 1, 1], r_d[..., 2, 2]], -1)
    assert set(np.argmax(d, axis=-1).ravel()) == {0, 1, 2, 3}


def test_attitude_features_flag_the_target_point():
    sc = resolve_scenario("pereira2022")
    x = _states(np.random.default_rng(1), (1, 2))
    x[0, 1, :3] = sc.pointing_target
    out = np.empty((1, 2, 4)), np.empty((1, 2, 3)), np.empty((1, 2, 4)), np.empty((1, 2))
    assert attitude_features(x, np.asarray(sc.pointing_target, dtype=float),
                             np.asarray(sc.pointing_reference), sc.mean_motion, POINTING_MIN_SINE, *out) == 1


@pytest.mark.parametrize("overrides", [{}, {"thrust_frame": "body"}, {"randomize": True}])
def test_compiled_core_matches_the_numpy_core(overrides):
    sc = resolve_scenario("pereira2022", **overrides)
    fast, ref = ServicingCore(sc, batch=3), ServicingCore(sc, batch=3)
    assert fast._ref_kernel is not None and fast._att_kernel is not None
    ref._ref_kernel = ref._att_kernel = None
    ref.model = RelativeModel(sc.dynamics, ref.orbit, ref.h, method="numpy")
    rng = np.random.default_rng(2)
    x0 = fast.sample_initial_state(rng, 3)
    for core in (fast, ref):
        core.reset(x0)
    np.testing.assert_allclose(fast.observe(), ref.observe(), rtol=0, atol=1e-6)
    for _ in range(30):
        a = rng.uniform(-1, 1, (3, fast.n_agents, 6)) * np.asarray(sc.u_max)
        rf, rr = fast.step(a), ref.step(a)
        for key, val in rr.info.items():
            if val.dtype.kind in "biu":
                np.testing.assert_array_equal(rf.info[key], val, err_msg=key)
            else:
                np.testing.assert_allclose(rf.info[key], val, rtol=TOL, atol=TOL, err_msg=key)
        np.testing.assert_allclose(rf.rewards, rr.rewards, rtol=TOL, atol=TOL)
        np.testing.assert_array_equal(rf.terminated, rr.terminated)
        np.testing.assert_allclose(fast.observe(), ref.observe(), rtol=0, atol=1e-6)


@pytest.mark.parametrize("overrides", [{}, {"randomize": True}, {"substeps": 3}, {"dynamics": "j2_drag"},
                                       {"terminate_on_collision": False}])
def test_fused_step_matches_the_glued_kernels_bit_for_bit(overrides):
    """The one-pass step (satenv.envs._servicing_kernel.step) against the numpy glue around the
    compiled truth, attitude and reference kernels: the same numbers, dtypes and key order,
    through step, step_observe and partial resets."""
    sc = resolve_scenario("pereira2022", **overrides)
    fast, ref = ServicingCore(sc, batch=4), ServicingCore(sc, batch=4)
    assert fast._fused_applies()
    ref._fused = None
    rng = np.random.default_rng(3)
    x0 = fast.sample_initial_state(rng, 4)
    for core in (fast, ref):
        core.reset(x0)
    for k in range(40):
        a = rng.uniform(-1, 1, (4, fast.n_agents, 6)) * np.asarray(sc.u_max)
        if k % 2:
            (rf, of), (rr, orr) = fast.step_observe(a), ref.step_observe(a)
            assert of.dtype == orr.dtype and np.array_equal(of, orr)
            assert rf.finite.all()
        else:
            rf, rr = fast.step(a), ref.step(a)
        assert_same_step(rf, rr)
        for got, want in ((fast.x, ref.x), (fast.chief, ref.chief), (fast.t, ref.t), (fast.observe(), ref.observe()),
                          (fast.global_state(), ref.global_state())):
            np.testing.assert_array_equal(got, want)
        if rf.terminated.any():
            idx = np.flatnonzero(rf.terminated)
            x1 = fast.sample_initial_state(rng, len(idx))
            fi, ri = fast.reset(x1, idx), ref.reset(x1, idx)
            for key, val in ri.items():
                np.testing.assert_array_equal(fi[key], val, err_msg=key)


def test_fused_step_applies_only_where_it_is_exact():
    assert ServicingCore(resolve_scenario("pereira2022", thrust_frame="body"))._fused is None
    assert ServicingCore(resolve_scenario("pereira2022", dynamics="cw"))._fused is None
    assert ServicingCore(resolve_scenario("pereira2022"))._fused_applies()

