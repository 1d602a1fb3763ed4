"""The DOP853 truth propagation (``RelativeModel(..., integrator="dop853")``): the tableau, its
order, the compiled span kernel (``satenv.dynamics._span_kernel``) against the numpy reference
and the RK4 reference, and against the independent truth of ``tests/truth.py``.

Tolerances:

* kernel vs numpy DOP853, one input step per DOP853 step: 1e-12 relative, as
  ``tests/test_truth_kernel.py`` (the same formulas; measured ~2e-18);
* one DOP853 step spanning 20 input steps of 0.25 s vs 20 RK4 steps of the numpy reference:
  1e-10 relative, as ``tests/test_cluster_kernel.py``: both integrate the same ODE far below
  rounding of the chief's 7e6 m (RK4 at 0.25 s and DOP853 at 5 s have truncation errors of
  ~1e-14 m per step); the staircase of the inputs inside the span enters exactly (measured
  ~2e-12 relative with constant inputs, ~3e-13 with the cluster's sinusoid disturbance;
  deviations that jump by 1e-4 m/s^2 at every input step: ~6e-10 m);
* against the truth: ``POS_TOL`` (1 cm after one orbit) of ``tests/test_dynamics_validation.py``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import test_dynamics_drag as D
import test_dynamics_validation as V
import truth as T

from satenv import dynamics as sd
from satenv.dynamics import _dop853
from satenv.dynamics.integrators import integrate

pytest.importorskip("numba")

KERNEL_RTOL = 1e-12
SPAN_RTOL = 1e-10
SPAN_DT = 2.5   # s, input step of the truth comparisons: two per DOP853 step of 5 s
SPAN_THRUST = 1e-3   # m/s^2, largest LVLH thrust component of the staircase comparison


def _states(rng, batch, m):
    return rng.normal(size=(batch, m, 6)) * np.array([800.0, 800.0, 800.0, 0.5, 0.5, 0.5])


def _cluster_inputs(rng, steps, batch, m, h=0.25):
    """Commands held over 20 physics steps and the li2022 sinusoid disturbance at every step
    (``propagate``'s ``u`` and ``common``)."""
    cmd = np.repeat(rng.uniform(-0.02, 0.02, (steps // 20 + 1, batch, m, 3)), 20, axis=0)[:steps]
    ts = h * np.arange(steps)[:, None] + np.zeros((steps, batch))
    return cmd, sd.sinusoid_disturbance(ts, 0.002)


def test_tableau_is_scipys():
    from scipy.integrate._ivp import dop853_coefficients as ref

    assert np.array_equal(_dop853.A, ref.A[:12, :12])
    assert np.array_equal(_dop853.B, ref.B)
    assert np.array_equal(_dop853.C, ref.C[:12])


def test_step_is_eighth_order():
    def f(_t, y):
        return np.array([y[1], -y[0]])

    errs = [abs(integrate(f, 0.0, np.array([1.0, 0.0]), h, round(4 / h), "dop853")[-1, 0] - math.cos(4))
            for h in (0.5, 0.25)]
    assert 7.5 <= math.log2(errs[0] / errs[1]) <= 8.5, errs


@pytest.mark.parametrize("case", list(V.ORBIT_CASES))
@pytest.mark.parametrize("model", ["nonlinear", "j2", "j2_drag"])
def test_kernel_matches_the_numpy_dop853(model, case):
    orbit = V._orbit(case)
    rng = np.random.default_rng(1)
    x = _states(rng, 3, 5)
    for dt, steps in ((0.25, 1), (12.0, 4)):     # one step; input steps longer than a DOP853 step
        kern = sd.RelativeModel(model, orbit, dt, integrator="dop853", method="kernel")
        ref = sd.RelativeModel(model, orbit, dt, integrator="dop853", method="numpy")
        assert kern._cache["kernel"] is not None and ref._cache["kernel"] is None
        chief = np.tile(ref.initial_chief(), (3, 1))
        u = rng.uniform(-0.02, 0.02, (steps, 3, 5, 3))
        xr, cr, path_r = x, chief, []
        for s in range(steps):
            xr, cr = ref.step(xr, u[s], cr)
            path_r.append(xr[..., :3])
        xk, ck, path = kern.propagate(x, u, chief, positions=True)
        np.testing.assert_allclose(xk, xr, rtol=KERNEL_RTOL, atol=KERNEL_RTOL * np.abs(xr).max())
        np.testing.assert_allclose(ck, cr, rtol=KERNEL_RTOL, atol=0)
        np.testing.assert_allclose(path, np.array(path_r), rtol=KERNEL_RTOL, atol=KERNEL_RTOL * 1e3)


@pytest.mark.parametrize("case", list(V.ORBIT_CASES))
@pytest.mark.parametrize("model", ["nonlinear", "j2", "j2_drag"])
def test_span_matches_the_rk4_reference(model, case):
    """45 physics steps of 0.25 s (spans of 20, 20 and 5) against 45 RK4 steps; the staircase of the
    inputs matters far above the tolerance (holding each span's first input instead moves the
    states by ~1e4 times it)."""
    orbit = V._orbit(case)
    kern = sd.RelativeModel(model, orbit, 0.25, integrator="dop853", method="kernel")
    ref = sd.RelativeModel(model, orbit, 0.25, method="numpy")
    assert kern.group == 20
    rng = np.random.default_rng(2)
    x = _states(rng, 3, 5)
    chief = np.tile(ref.initial_chief(), (3, 1))
    cmd, dist = _cluster_inputs(rng, 45, 3, 5)
    u = cmd + dist[:, :, None, :]
    xr, cr, path_r = x, chief, []
    for s in range(len(u)):
        xr, cr = ref.step(xr, u[s], cr)
        path_r.append(xr[..., :3])
    scale = np.abs(xr).max()
    for inputs in ({"u": cmd, "common": dist}, {"u": u}):   # apart, or added up (no shared table)
        xk, ck, path = kern.propagate(x, inputs["u"], chief, positions=True, common=inputs.get("common"))
        np.testing.assert_allclose(xk, xr, rtol=SPAN_RTOL, atol=SPAN_RTOL * scale)
        np.testing.assert_allclose(ck, cr, rtol=SPAN_RTOL, atol=0)
        np.testing.assert_allclose(path, np.array(path_r), rtol=SPAN_RTOL, atol=SPAN_RTOL * 1e3)
    held = u.copy()
    for s0 in (0, 20, 40):
        held[s0:s0 + 20] = u[s0]
    xh = kern.propagate(x, held, chief)[0]
    assert np.abs(xh - xr).max() > 1e3 * SPAN_RTOL * scale


def test_span_tables_are_shared_only_by_equal_deviations():
    """Copies with the same chief and equal or different input staircases, alone or in one batch:
    the same answers bit for bit (a deviation table is reused only where it applies)."""
    orbit = V._orbit("eccentric")
    kern = sd.RelativeModel("j2_drag", orbit, 0.25, integrator="dop853")
    rng = np.random.default_rng(3)
    x = _states(rng, 5, 4)
    chief = np.tile(kern.initial_chief(), (5, 1))
    chief[3] = kern.propagate(np.zeros((1, 6)), np.zeros((3, 1, 3)), chief[3])[1]
    cmd, dist = _cluster_inputs(rng, 20, 1, 4)
    other = rng.uniform(-0.02, 0.02, (20, 1, 4, 3))
    pick = [0, 0, 1, 0, 0]   # copy 2 has its own staircase, copy 3 its own chief
    u = np.concatenate([(cmd, other)[k] for k in pick], axis=1)
    common = np.concatenate([(dist, np.zeros((20, 1, 3)))[k] for k in pick], axis=1)
    xk, ck, path = kern.propagate(x, u, chief, positions=True, common=common)
    for i in range(5):
        xi, ci, pi = kern.propagate(x[i:i + 1], u[:, i:i + 1], chief[i:i + 1], positions=True,
                                    common=common[:, i:i + 1])
        np.testing.assert_array_equal(xk[i:i + 1], xi)
        np.testing.assert_array_equal(ck[i:i + 1], ci)
        np.testing.assert_array_equal(path[:, i:i + 1], pi)
    ref = sd.RelativeModel("j2_drag", orbit, 0.25, method="numpy")   # and the answers are right
    xr, cr = x, chief
    for s in range(20):
        xr, cr = ref.step(xr, u[s] + common[s][:, None, :], cr)
    np.testing.assert_allclose(xk, xr, rtol=SPAN_RTOL, atol=SPAN_RTOL * np.abs(xr).max())


@pytest.mark.parametrize("case", list(V.ORBIT_CASES))
@pytest.mark.parametrize("model", list(V.TRUTH_MODEL))
def test_span_matches_the_independent_truth(model, case):
    """Steps of 2.5 s, two per DOP853 step, over one orbit in calls of 40: the positions after every
    fourth step (10 s, the truth's samples; half of them interpolated inside a span) and the
    states at every call's end."""
    orbit = V._orbit(case)
    steps, _ = V._one_orbit(case)
    prop = sd.RelativeModel(model, orbit, SPAN_DT, integrator="dop853")
    assert prop.group == 2
    x0 = V._deputies(orbit.n)
    truth = V._truth(model, case)
    per = round(V.DT / SPAN_DT)
    x, chief = x0, prop.initial_chief()
    pos_err = vel_err = 0.0
    chunk = 40
    for k0 in range(0, steps * per, chunk):
        n = min(chunk, steps * per - k0)
        x, chief, path = prop.propagate(x, np.zeros((n, len(x0), 3)), chief, positions=True)
        ends = np.arange(k0 + 1, k0 + n + 1)
        sel = ends % per == 0
        pos_err = max(pos_err, np.linalg.norm(path[sel] - truth[ends[sel] // per, :, :3], axis=-1).max())
        if (k0 + n) % per == 0:
            vel_err = max(vel_err, np.linalg.norm(x[:, 3:] - truth[(k0 + n) // per, :, 3:], axis=-1).max())
    assert pos_err <= V.POS_TOL, pos_err
    assert vel_err <= V.POS_TOL * orbit.n * 10, vel_err


@pytest.mark.parametrize("model", list(V.TRUTH_MODEL))
def test_span_thrust_staircase_matches_truth(model):
    """LVLH thrust changing at every 2.5 s step (inside each DOP853 step) against the truth that
    rotates it with the chief's instantaneous frame inside the ODE, one solve per step."""
    orbit = V._orbit("circular")
    x0 = V._deputies(orbit.n)[:2]
    rng = np.random.default_rng(7)
    u = rng.uniform(-SPAN_THRUST, SPAN_THRUST, size=(V.THRUST_STEPS, len(x0), 3))
    xt = T.truth_relative_thrust(V.TRUTH_MODEL[model], x0, V._chief_rv_truth("circular"), SPAN_DT, u)
    prop = sd.RelativeModel(model, orbit, SPAN_DT, integrator="dop853")
    x, _, path = prop.propagate(x0, u, prop.initial_chief(), positions=True)
    free = prop.propagate(x0, np.zeros_like(u), prop.initial_chief())[0]
    err = np.linalg.norm(path - xt[1:, :, :3], axis=-1).max()
    assert err <= V.POS_TOL, err
    assert np.linalg.norm(x[:, :3] - free[:, :3], axis=-1).min() > 100 * V.POS_TOL


def test_j2_drag_span_matches_independent_truth():
    """``j2_drag`` with differential drag over one orbit (the truth of ``tests/test_dynamics_drag.py``)."""
    orbit = sd.Orbit(a=T.RE + 500e3, i=math.radians(51.6))
    x0 = np.array([[0.0, 1000.0, 0.0, 0.0, 0.0, 0.0], [100.0, 0.0, 50.0, 0.0, -2 * orbit.n * 100, 0.0]])
    steps = round(orbit.period / SPAN_DT)
    chief0 = orbit.rv
    deps0 = T.lvlh_to_eci(chief0, D._truth_acc(chief0[:3], chief0[3:], D.B_CHIEF), x0)
    chief = D._propagate(chief0, D.B_CHIEF, steps * SPAN_DT)
    deps = np.array([D._propagate(d, D.B_DEPUTY, steps * SPAN_DT) for d in deps0])
    truth = T.eci_to_lvlh(chief, D._truth_acc(chief[:3], chief[3:], D.B_CHIEF), deps)
    force = sd.ForceModel(j2=True, drag=True, ballistic_chief=D.B_CHIEF, ballistic_deputy=D.B_DEPUTY)
    prop = sd.RelativeModel("j2_drag", orbit, SPAN_DT, force=force, integrator="dop853")
    x, c = x0, prop.initial_chief()
    for k0 in range(0, steps, 200):
        x, c, _ = prop.propagate(x, np.zeros((min(200, steps - k0), 2, 3)), c)
    err = np.linalg.norm(x[:, :3] - truth[:, :3], axis=-1).max()
    assert err <= V.POS_TOL, err
