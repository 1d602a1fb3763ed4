"""The compiled attitude step (issue 25) against the numpy reference of
``satenv.dynamics.attitude`` (which ``tests/test_attitude.py`` checks against two inertial bodies
integrated independently).

Tolerance 1e-12 (absolute, on unit quaternions and on rates of order 1 rad/s): the kernel
evaluates eq. 10 and 13-16 in component arithmetic and applies ``J_f^-1`` as a precomputed
inverse instead of a solve, so the two differ by rounding only (measured ~1e-15 after 200 steps).
"""

from __future__ import annotations

import numpy as np
import pytest

from satenv.dynamics.attitude import attitude_step

pytest.importorskip("numba")

J_F = np.array([[10.0, 2.5, 3.5], [2.5, 10.0, 4.5], [3.5, 4.5, 10.0]])
J_L = np.array([[8.0, 1.0, 0.5], [1.0, 12.0, -0.7], [0.5, -0.7, 9.0]])   # leader terms non-zero


def _random(rng, shape):
    q = rng.normal(size=(*shape, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True), rng.normal(size=(*shape, 3)), rng.normal(size=(*shape, 3))


@pytest.mark.parametrize("substeps", [1, 3])
def test_kernel_matches_the_numpy_reference(substeps):
    rng = np.random.default_rng(0)
    q, w, torque = _random(rng, (4, 3))
    omega_l = np.array([0.05, -0.1, 0.3])
    qk, wk, qr, wr = q, w, q, w
    for _ in range(200):
        qk, wk = attitude_step(qk, wk, torque, 0.1, J_F, J_L, omega_l, substeps, method="kernel")
        qr, wr = attitude_step(qr, wr, torque, 0.1, J_F, J_L, omega_l, substeps, method="numpy")
    assert qk.shape == qr.shape == (4, 3, 4) and wk.shape == (4, 3, 3)
    np.testing.assert_allclose(qk, qr, rtol=0, atol=1e-12)
    np.testing.assert_allclose(wk, wr, rtol=0, atol=1e-12)
    assert np.abs(wr - w).max() > 0.1          # the motion is not trivial


def test_kernel_broadcasts_like_the_reference_and_can_fail():
    rng = np.random.default_rng(1)
    q, w, torque = _random(rng, (5,))
    omega_l = np.array([0.0, 0.0, 0.2])
    a = attitude_step(q, w, torque[0], 0.2, J_F, J_L, omega_l, method="kernel")
    b = attitude_step(q, w, torque[0], 0.2, J_F, J_L, omega_l, method="numpy")
    np.testing.assert_allclose(a[0], b[0], rtol=0, atol=1e-14)
    np.testing.assert_allclose(a[1], b[1], rtol=0, atol=1e-14)
    c = attitude_step(q, w, torque[0], 0.2, J_F * (1 + 1e-9), J_L, omega_l, method="kernel")
    assert np.abs(c[1] - b[1]).max() > 1e-12   # a 1e-9 change of the inertia is seen


def test_kernel_rejects_a_zero_quaternion_and_a_varying_leader_rate():
    with pytest.raises(ValueError, match="zero quaternion"):
        attitude_step(np.zeros(4), np.zeros(3), np.zeros(3), 0.1, J_F, J_L, np.zeros(3), method="kernel")
    with pytest.raises(ValueError, match="omega_l"):
        attitude_step(np.array([1.0, 0, 0, 0]), np.zeros(3), np.zeros(3), 0.1, J_F, J_L,
                      np.zeros((2, 3)), method="kernel")
    with pytest.raises(ValueError, match="method"):
        attitude_step(np.array([1.0, 0, 0, 0]), np.zeros(3), np.zeros(3), 0.1, J_F, J_L, np.zeros(3), method="x")
