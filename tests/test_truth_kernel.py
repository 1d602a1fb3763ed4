"""The compiled truth kernel (``satenv.dynamics._truth_kernel``, issue 25) against the numpy
reference it replaces, and against the independent truth of ``tests/truth.py``.

Tolerance against the reference: 1e-12 relative on the states after many steps. The kernel
evaluates the reference's formulas in the reference's order; the only differences are the
rounding of the LVLH <-> ECI round trips that the reference performs at every step and the
kernel skips (each a rotation, ~1e-16 relative), accumulated over the steps: measured
~2e-15 over 40 steps, so 1e-12 leaves room for longer runs and still fails on a change of a
formula (a 1e-6 relative change of the J2 coefficient alone moves the states by ~6e-10 relative
within 5 minutes: ``test_kernel_detects_a_changed_formula``).
Against the truth: the same ``POS_TOL`` (1 cm after one orbit) as
``tests/test_dynamics_validation.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
import test_dynamics_validation as V

from satenv import dynamics as sd

pytest.importorskip("numba")

RTOL = 1e-12


def _states(rng, batch, m):
    x = rng.normal(size=(batch, m, 6)) * np.array([800.0, 800.0, 800.0, 0.5, 0.5, 0.5])
    return x


@pytest.mark.parametrize("case", list(V.ORBIT_CASES))
@pytest.mark.parametrize("model", ["nonlinear", "j2", "j2_drag"])
def test_kernel_matches_the_numpy_reference(model, case):
    orbit = V._orbit(case)
    kern = sd.RelativeModel(model, orbit, 0.25, method="kernel")
    ref = sd.RelativeModel(model, orbit, 0.25, method="numpy")
    assert kern._cache["kernel"] is not None and ref._cache["kernel"] is None
    rng = np.random.default_rng(1)
    x = _states(rng, 3, 5)
    chief = np.tile(ref.initial_chief(), (3, 1))
    u = rng.uniform(-0.02, 0.02, (40, 3, 5, 3))
    xr, cr, path_r = x, chief, []
    for s in range(len(u)):
        xr, cr = ref.step(xr, u[s], cr)
        path_r.append(xr[..., :3])
    xk, ck, path = kern.propagate(x, u, chief, positions=True)
    np.testing.assert_allclose(xk, xr, rtol=RTOL, atol=RTOL * np.abs(xr).max())
    np.testing.assert_allclose(ck, cr, rtol=RTOL, atol=0)
    np.testing.assert_allclose(path, np.array(path_r), rtol=RTOL, atol=RTOL * 1e3)
    # one step at a time through step(), several substeps, broadcast inputs and chief
    k1 = sd.RelativeModel(model, orbit, 12.0, method="kernel")
    r1 = sd.RelativeModel(model, orbit, 12.0, method="numpy")
    assert k1.substeps == 3
    a, b = k1.step(x, u[0, 0], ref.initial_chief()), r1.step(x, u[0, 0], ref.initial_chief())
    assert a[1].shape == b[1].shape == (3, 6)
    np.testing.assert_allclose(a[0], b[0], rtol=RTOL, atol=RTOL * 1e3)
    np.testing.assert_allclose(a[1], b[1], rtol=RTOL, atol=0)
    # the numpy fallback of propagate() gives the loop's answer too
    xn, cn, pn = ref.propagate(x, u[:4], chief, positions=True)
    xl, cl = x, chief
    for s in range(4):
        xl, cl = ref.step(xl, u[s], cl)
    np.testing.assert_array_equal(xn, xl)
    np.testing.assert_array_equal(pn[-1], xl[..., :3])


def test_copies_with_different_chiefs_match_the_reference():
    """The chief's track is shared only by consecutive copies with the same chief: alternating and
    repeated chiefs give each copy the reference's answer."""
    orbit = V._orbit("eccentric")
    kern = sd.RelativeModel("j2_drag", orbit, 0.25, method="kernel")
    ref = sd.RelativeModel("j2_drag", orbit, 0.25, method="numpy")
    rng = np.random.default_rng(4)
    c0 = ref.initial_chief()
    c1 = ref.step(np.zeros((1, 6)), None, c0)[1]
    chief = np.stack([c0, c1, c0, c0, c1, c1])
    x = _states(rng, 6, 4)
    u = rng.uniform(-0.02, 0.02, (8, 6, 4, 3))
    xr, cr = x, chief
    for s in range(len(u)):
        xr, cr = ref.step(xr, u[s], cr)
    xk, ck, _ = kern.propagate(x, u, chief)
    np.testing.assert_allclose(xk, xr, rtol=RTOL, atol=RTOL * np.abs(xr).max())
    np.testing.assert_allclose(ck, cr, rtol=RTOL, atol=0)
    assert not np.array_equal(ck[0], ck[1])


def test_kernel_detects_a_changed_formula():
    """The tolerance can fail: a 1e-6 change of the J2 coefficient is far outside it."""
    orbit = V._orbit("circular")
    force = sd.FORCE_MODELS["j2"]
    from dataclasses import replace
    kern = sd.RelativeModel("j2", orbit, 5.0, force=replace(force, j2_coef=force.j2_coef * (1 + 1e-6)))
    ref = sd.RelativeModel("j2", orbit, 5.0, method="numpy")
    x = _states(np.random.default_rng(2), 2, 3)
    xs_k, xs_r = x, x
    ck = cr = ref.initial_chief()
    for _ in range(60):
        xs_k, ck = kern.step(xs_k, None, ck)
        xs_r, cr = ref.step(xs_r, None, cr)
    assert np.abs(xs_k - xs_r).max() > 100 * RTOL * np.abs(xs_r).max()


@pytest.mark.parametrize("case", list(V.ORBIT_CASES))
@pytest.mark.parametrize("model", list(V.TRUTH_MODEL))
def test_hoisted_kernel_matches_the_independent_truth(model, case):
    """Many steps per kernel call (frames converted at the ends only) over one orbit, the
    positions after every step and the full states at every call's end, against the truth."""
    orbit = V._orbit(case)
    steps, _ = V._one_orbit(case)
    prop = sd.RelativeModel(model, orbit, V.DT, method="kernel")
    x0 = V._deputies(orbit.n)
    truth = V._truth(model, case)
    chunk = 25
    x, chief = x0, prop.initial_chief()
    pos_err = vel_err = 0.0
    for k0 in range(0, steps, chunk):
        n = min(chunk, steps - k0)
        x, chief, path = prop.propagate(x, np.zeros((n, len(x0), 3)), chief, positions=True)
        pos_err = max(pos_err, np.linalg.norm(path - truth[k0 + 1:k0 + 1 + n, :, :3], axis=-1).max())
        vel_err = max(vel_err, np.linalg.norm(x[:, 3:] - truth[k0 + n, :, 3:], axis=-1).max())
    assert pos_err <= V.POS_TOL, pos_err
    assert vel_err <= V.POS_TOL * orbit.n * 10, vel_err
