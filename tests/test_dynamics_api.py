"""Unit tests of satenv.dynamics helpers: shapes, bad input, saturation, prediction matrices."""

import math

import numpy as np
import pytest

from satenv import dynamics as d

ORBIT = d.Orbit(a=6878137.0, i=math.radians(51.6))


def test_prediction_matrices_match_recursion():
    a, b = d.cw_matrices(ORBIT.n, 0.1)
    cal_a, cal_b = d.prediction_matrices(a, b, 5)
    rng = np.random.default_rng(0)
    x0, us = rng.normal(size=6), rng.normal(size=(5, 3))
    x, stacked = x0, []
    for k in range(5):
        x = a @ x + b @ us[k]
        stacked.append(x)
    np.testing.assert_allclose(cal_a @ x0 + cal_b @ us.ravel(), np.concatenate(stacked), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("batch", [(), (3,), (2, 5)])
def test_relative_model_is_batch_first(batch):
    rng = np.random.default_rng(1)
    x = rng.normal(size=(*batch, 4, 6)) * 100
    u = rng.normal(size=(*batch, 4, 3)) * 1e-3
    chief = np.broadcast_to(ORBIT.rv, (*batch, 6))
    for model in d.MODELS:
        prop = d.RelativeModel(model, ORBIT, 1.0)
        xn, cn = prop.step(x, u, chief)
        assert xn.shape == x.shape and cn.shape == chief.shape
        # batched result equals the per-element result
        if batch:
            idx = (0,) * len(batch)
            x1, _ = prop.step(x[idx], u[idx], chief[idx])
            np.testing.assert_allclose(xn[idx], x1, rtol=1e-12, atol=1e-9)


def test_saturation():
    u = np.array([[3.0, -4.0, 0.0], [0.1, 0.2, 0.2]])
    np.testing.assert_allclose(d.saturate_norm(u, 1.0)[0], [0.6, -0.8, 0.0])
    np.testing.assert_allclose(d.saturate_norm(u, 1.0)[1], u[1])
    np.testing.assert_allclose(d.saturate_box(u, 1.0)[0], [1.0, -1.0, 0.0])
    np.testing.assert_allclose(d.delta_v(u, 2.0), [10.0, 0.6])
    np.testing.assert_allclose(d.unit_box_to_accel(np.array([2.0, -0.5, 0.0]), 6.0), [6.0, -3.0, 0.0])
    with pytest.raises(ValueError, match="saturation mode"):
        d.unit_box_to_accel(u, 1.0, mode="sphere")


def test_disturbances_bounded_and_seeded():
    w = d.sinusoid_disturbance(np.linspace(0, 1000, 101), 0.1)
    assert w.shape == (101, 3) and np.abs(w).max() <= 0.1 + 1e-15
    np.testing.assert_allclose(w[0], 0.1 * np.sin([np.pi / 3, -2 * np.pi / 3, np.pi / 2]))
    dist = d.BoundedRandomDisturbance(0.01)
    a = dist.sample(np.random.default_rng(3), (100, 4))
    b = dist.sample(np.random.default_rng(3), (100, 4))
    np.testing.assert_array_equal(a, b)
    assert np.linalg.norm(a, axis=-1).max() <= 0.01


def test_integrators_order():
    # y' = y, exact e^t: halving the step divides the RK4 error by ~16 and Euler's by ~2
    f = lambda t, y: y  # noqa: E731
    errs = {}
    for method in ("euler", "rk4"):
        errs[method] = [abs(d.integrate(f, 0.0, np.array(1.0), 1.0 / n, n, method)[-1] - math.e)
                        for n in (16, 32)]
    assert 1.8 < errs["euler"][0] / errs["euler"][1] < 2.2
    assert 14 < errs["rk4"][0] / errs["rk4"][1] < 18


@pytest.mark.parametrize("bad, match", [
    (dict(model="hill"), "unknown dynamics model 'hill'"),
    (dict(x0=np.zeros((2, 5))), r"x0 must have shape \(\.\.\., 6\), got shape \(2, 5\)"),
    (dict(x0=np.zeros(6)), r"x0 must have shape \(M, 6\)"),
    (dict(x0=np.array([[np.nan, 0, 0, 0, 0, 0]])), "x0 must be finite"),
    (dict(u=np.zeros((3, 1, 2))), r"u must have shape"),
    (dict(u=np.full((3, 1, 3), np.inf)), "u must be finite"),
    (dict(dt=-1.0), "dt"),
    (dict(steps=2.5), "steps must be an int >= 0"),
])
def test_simulate_rejects_bad_input(bad, match):
    kwargs = dict(model="cw", x0=np.zeros((1, 6)), orbit=ORBIT, dt=1.0, steps=3)
    kwargs.update(bad)
    with pytest.raises(ValueError, match=match):
        d.simulate(kwargs.pop("model"), kwargs.pop("x0"), **kwargs)


@pytest.mark.parametrize("kwargs, match", [
    (dict(a=-7e6), "inside the Earth"),
    (dict(a=6e6), "inside the Earth"),
    (dict(a=7e6, e=1.0), "0 <= e < 1"),
    (dict(a=7e6, e=-0.1), "0 <= e < 1"),
    (dict(a=7e6, i=90.0), "radians"),
    (dict(a=float("nan")), "finite"),
    (dict(a="7000 km"), "real number"),
])
def test_orbit_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        d.Orbit(**kwargs)


def test_orbit_is_frozen_and_elements_round_trip():
    orbit = d.Orbit(a=7000e3, e=0.05, i=0.9, raan=1.0, argp=2.0, nu=3.0)
    with pytest.raises(AttributeError):
        orbit.a = 1.0
    back = d.rv_to_elements(orbit.rv)
    for name in ("a", "e", "i", "raan", "argp", "nu"):
        assert getattr(back, name) == pytest.approx(getattr(orbit, name), rel=1e-10, abs=1e-10)
    assert orbit.period == pytest.approx(2 * math.pi * math.sqrt(7000e3**3 / d.MU_EARTH))


def test_acceleration_kernel_has_one_home_and_no_import_circle():
    """forces.py holds the acceleration kernel and imports no other satenv.dynamics module but
    constants; _soa.py imports it from there (no circle)."""
    import ast
    import pathlib

    import satenv.dynamics as dyn

    root = pathlib.Path(dyn.__file__).parent
    tree = ast.parse((root / "forces.py").read_text())
    relative = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.level == 1}
    assert relative == {"constants"}
    from satenv.dynamics import _soa, forces
    assert _soa.acceleration_soa is forces.acceleration_soa
