"""satenv.dynamics.attitude: quaternions, relative rotational dynamics, thrusters, pointing."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from satenv.dynamics.attitude import (
    attitude_derivative,
    attitude_step,
    desired_angular_velocity,
    matrix_to_quat,
    pointing_error,
    pointing_frame,
    pointing_rate,
    quat_conjugate,
    quat_error,
    quat_kinematics,
    quat_multiply,
    quat_normalize,
    quat_to_euler_xyz,
    quat_to_matrix,
    relative_angular_acceleration,
    skew,
    thruster_matrices,
)

J_F = np.array([[10.0, 2.5, 3.5], [2.5, 10.0, 4.5], [3.5, 4.5, 10.0]])


def random_quats(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def test_hamilton_product_is_eq8():
    rng = np.random.default_rng(0)
    qf, ql = random_quats(rng, 2)
    ef, vf, el, vl = qf[0], qf[1:], ql[0], ql[1:]
    expected = np.concatenate([[ef * el + vf @ vl], el * vf - ef * vl - skew(vf) @ vl])
    np.testing.assert_allclose(quat_multiply(qf, quat_conjugate(ql)), expected, atol=1e-15)
    np.testing.assert_allclose(quat_multiply(qf, quat_conjugate(qf)), [1, 0, 0, 0], atol=1e-15)


def test_rotation_matrix_and_inverse():
    rng = np.random.default_rng(1)
    q = random_quats(rng, 200)
    # include near-180 deg rotations (eta ~ 0), the hard case of the inverse map
    q[:3] = quat_normalize(np.array([[1e-9, 1, 0, 0], [0, 0.6, 0.8, 0], [1e-7, 0, 0, 1]]))
    r = quat_to_matrix(q)
    np.testing.assert_allclose(r @ np.swapaxes(r, 1, 2), np.broadcast_to(np.eye(3), r.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-14)
    back = matrix_to_quat(r)
    sign = np.sign(np.sum(back * q, axis=1, keepdims=True))
    np.testing.assert_allclose(back, sign * q, atol=1e-12)
    assert np.all(back[:, 0] >= 0)
    # a 90 deg rotation about z maps body x to reference y
    qz = np.array([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)])
    np.testing.assert_allclose(quat_to_matrix(qz) @ [1, 0, 0], [0, 1, 0], atol=1e-15)


def test_kinematics_eq10_is_body_rate_of_R():
    """d/dt R(q) = R(q) S(omega): R(q) maps body to reference, omega is in the body frame."""
    rng = np.random.default_rng(2)
    q = random_quats(rng, 1)[0]
    w = rng.normal(size=3)
    qdot = quat_kinematics(q, w)
    np.testing.assert_allclose(qdot, 0.5 * quat_multiply(q, np.concatenate([[0.0], w])), atol=1e-15)
    h = 1e-6
    rdot = (quat_to_matrix(q + h * qdot) - quat_to_matrix(q - h * qdot)) / (2 * h)
    np.testing.assert_allclose(rdot, quat_to_matrix(q) @ skew(w), atol=1e-8)


def test_quaternion_norm_preserved_by_integrator():
    rng = np.random.default_rng(3)
    q = random_quats(rng, 8)
    w = rng.uniform(-2, 2, size=(8, 3))
    torque = np.zeros((8, 3))   # torque-free tumbling: omega stays bounded
    omega_l = np.array([0.0, 0.0, 0.3])
    qn, wn = q.copy(), w.copy()
    for _ in range(500):
        qn, wn = attitude_step(qn, wn, torque, 0.2, J_F, 10 * np.eye(3), omega_l)
    np.testing.assert_allclose(np.linalg.norm(qn, axis=1), 1.0, atol=1e-14)
    # without the renormalisation plain RK4 drifts off the unit sphere at this step size
    y = np.concatenate([q, w], axis=1)
    for _ in range(500):
        k1 = attitude_derivative(y, torque, J_F, 10 * np.eye(3), omega_l)
        k2 = attitude_derivative(y + 0.1 * k1, torque, J_F, 10 * np.eye(3), omega_l)
        k3 = attitude_derivative(y + 0.1 * k2, torque, J_F, 10 * np.eye(3), omega_l)
        k4 = attitude_derivative(y + 0.2 * k3, torque, J_F, 10 * np.eye(3), omega_l)
        y = y + 0.2 / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert np.max(np.abs(np.linalg.norm(y[:, :4], axis=1) - 1.0)) > 1e-8


def test_zero_quaternion_rejected():
    with pytest.raises(ValueError, match="zero quaternion"):
        quat_normalize(np.zeros(4))


def _inertial_rhs(t, y, j_f, j_l, torque_f):
    """Independent model: both bodies' inertial attitudes and Euler's equations (eq. 11)."""
    qf, wf, ql, wl = y[:4], y[4:7], y[7:11], y[11:]
    dwf = np.linalg.solve(j_f, -np.cross(wf, j_f @ wf) + torque_f)
    dwl = np.linalg.solve(j_l, -np.cross(wl, j_l @ wl))
    return np.concatenate([quat_kinematics(qf, wf), dwf, quat_kinematics(ql, wl), dwl])


def test_relative_dynamics_match_two_inertial_bodies():
    """Eq. 13-17 (relative q, omega) agree with propagating both bodies inertially (DOP853)."""
    rng = np.random.default_rng(4)
    j_l = 10 * np.eye(3)                       # torque-free isotropic leader: omega_l constant
    omega_l = np.array([0.0, 0.0, 0.4])        # a fast frame rate so the coupling terms matter
    torque = np.array([0.3, -0.5, 0.2])
    qf0 = random_quats(rng, 1)[0]
    wf0 = rng.normal(size=3) * 0.5
    ql0 = np.array([1.0, 0, 0, 0])
    y0 = np.concatenate([qf0, wf0, ql0, omega_l])
    t_end = 20.0
    sol = solve_ivp(_inertial_rhs, (0, t_end), y0, method="DOP853", rtol=1e-12, atol=1e-12,
                    args=(J_F, j_l, torque))
    qf, wf, ql, wl = sol.y[:4, -1], sol.y[4:7, -1], sol.y[7:11, -1], sol.y[11:, -1]
    # relative attitude: R(q) = R_l^T R_f maps follower body -> leader body
    q_rel_true = quat_multiply(quat_conjugate(ql), qf)
    w_rel_true = wf - quat_to_matrix(q_rel_true).T @ wl
    q, w = qf0.copy(), wf0 - quat_to_matrix(qf0).T @ omega_l
    for _ in range(2000):
        q, w = attitude_step(q, w, torque, t_end / 2000, J_F, j_l, omega_l)
    sign = np.sign(q @ q_rel_true)
    np.testing.assert_allclose(sign * q, q_rel_true, atol=1e-8)
    np.testing.assert_allclose(w, w_rel_true, atol=1e-8)


def test_relative_acceleration_with_precessing_leader_and_leader_torque():
    """Eq. 15-16's leader terms: omega_dot = omega_f_dot + S(omega) R w_l - R w_l_dot."""
    rng = np.random.default_rng(5)
    j_l = np.array([[8.0, 1.0, 0.5], [1.0, 12.0, -0.7], [0.5, -0.7, 9.0]])
    q = random_quats(rng, 1)[0]
    w = rng.normal(size=3)
    w_l = rng.normal(size=3)
    tau_f, tau_l = rng.normal(size=3), rng.normal(size=3)
    r_fl = quat_to_matrix(q).T
    w_f = w + r_fl @ w_l
    wf_dot = np.linalg.solve(J_F, -np.cross(w_f, J_F @ w_f) + tau_f)
    wl_dot = np.linalg.solve(j_l, -np.cross(w_l, j_l @ w_l) + tau_l)
    expected = wf_dot + np.cross(w, r_fl @ w_l) - r_fl @ wl_dot
    got = relative_angular_acceleration(q, w, tau_f, J_F, j_l, w_l, torque_l=tau_l)
    np.testing.assert_allclose(got, expected, atol=1e-12)


def test_thruster_matrices_hand_cases():
    f_t, f_r = thruster_matrices([2.0, 4.0, 6.0])
    e = np.eye(6)
    # thruster 1: +z force at (Lx, Ly)/2 -> torque (Ly/2, -Lx/2, 0)
    np.testing.assert_array_equal(f_t @ e[0], [0, 0, 1])
    np.testing.assert_array_equal(f_r @ e[0], [2, -1, 0])
    np.testing.assert_array_equal(f_t @ e[1], [0, 0, -1])
    np.testing.assert_array_equal(f_r @ e[1], [2, -1, 0])
    np.testing.assert_array_equal(f_t @ e[2], [1, 0, 0])
    np.testing.assert_array_equal(f_r @ e[2], [0, 3, -2])
    np.testing.assert_array_equal(f_t @ e[3], [-1, 0, 0])
    np.testing.assert_array_equal(f_t @ e[4], [0, 1, 0])
    np.testing.assert_array_equal(f_r @ e[4], [3, 0, 1])
    np.testing.assert_array_equal(f_r @ e[5], [3, 0, 1])
    # a pure force (opposed pair) has no torque, a pure torque (equal pair) no force
    np.testing.assert_array_equal(f_r @ [1, -1, 0, 0, 0, 0], [0, 0, 0])
    np.testing.assert_array_equal(f_t @ [0, 0, 1, 1, 0, 0], [0, 0, 0])
    np.testing.assert_array_equal(f_r @ [0, 0, 1, 1, 0, 0], [0, 6, -4])
    # every column is r_i x F_i for the documented mounting points
    lx, ly, lz = 2.0, 4.0, 6.0
    r = 0.5 * np.array([[lx, ly, 0], [-lx, -ly, 0], [0, ly, lz], [0, -ly, -lz],
                        [lx, 0, -lz], [-lx, 0, lz]])
    np.testing.assert_allclose(np.cross(r, f_t.T).T, f_r)
    # the six inputs reach any force/torque: [F_t; F_r] is invertible for the paper's L
    f_t2, f_r2 = thruster_matrices([2, 2, 2])
    assert abs(np.linalg.det(np.vstack([f_t2, f_r2]))) > 1e-6


def test_pointing_frame_eq44_hand_case():
    # eq. 44 literally (a = p) with an off-centre target t = [10, 0, 0]:
    # t - p = [10, 15, 0], k_d x p = [0, 0, -150] / |t - p|
    r_d = pointing_frame(np.array([0.0, -15.0, 0.0]), target=[10.0, 0, 0])
    s = np.sqrt(325.0)
    np.testing.assert_allclose(r_d[:, 2], np.array([10, 15, 0]) / s, atol=1e-15)   # k_d
    np.testing.assert_allclose(r_d[:, 1], [0, 0, -1], atol=1e-15)                   # j_d
    np.testing.assert_allclose(r_d[:, 0], np.array([15, -10, 0]) / s, atol=1e-15)  # i_d
    # target at the centre with the orbit normal as reference a
    r_d = pointing_frame(np.array([0.0, -15.0, 0.0]), reference=[0, 0, 1])
    np.testing.assert_allclose(r_d, [[0, 1, 0], [0, 0, 1], [1, 0, 0]], atol=1e-15)
    # degenerate reference (a parallel to k_d): falls back to a valid right-handed frame
    r_d = pointing_frame(np.array([[0.0, 0, -15], [3.0, 4, 12]]), reference=[0, 0, 1])
    np.testing.assert_allclose(r_d @ np.swapaxes(r_d, 1, 2), np.broadcast_to(np.eye(3), (2, 3, 3)), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(r_d), 1.0, atol=1e-14)
    np.testing.assert_allclose(r_d[0, :, 2], [0, 0, 1], atol=1e-15)
    with pytest.raises(ValueError, match="coincides"):
        pointing_frame(np.zeros(3))


def test_desired_quaternion_points_body_z_at_target():
    rng = np.random.default_rng(6)
    p = rng.normal(size=(50, 3)) * 20
    q_d = matrix_to_quat(pointing_frame(p, reference=[1, 1, 1]))
    np.testing.assert_allclose(pointing_error(q_d, p), 0.0, atol=2e-7)
    q = random_quats(rng, 50)
    e = quat_error(q, q_d)
    assert np.all(e[:, 0] >= 0)
    np.testing.assert_allclose(quat_error(q_d, q_d), np.tile([1.0, 0, 0, 0], (50, 1)), atol=1e-14)


def test_pointing_rate_eq45_tracks_the_moving_line_of_sight():
    p0, v = np.array([3.0, -14.0, 5.0]), np.array([0.4, 0.9, -0.3])
    h = 1e-6
    r_d = pointing_frame(p0, reference=[1, 1, 1])
    w_d = pointing_rate(p0, v, r_d)
    k = lambda p: (-p) / np.linalg.norm(p)  # noqa: E731
    k_dot = (k(p0 + h * v) - k(p0 - h * v)) / (2 * h)
    np.testing.assert_allclose(np.cross(r_d @ w_d, r_d[:, 2]), k_dot, atol=1e-8)
    assert w_d[2] == 0.0
    # eq. 49 at q = q_d and n = 0: omega_d is that same rate in body components
    q_d = matrix_to_quat(r_d)
    np.testing.assert_allclose(desired_angular_velocity(q_d, r_d, w_d, 0.0), w_d, atol=1e-12)


def test_euler_xyz():
    a, b, c = 0.3, -0.7, 1.1
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    q = matrix_to_quat(rx @ ry @ rz)
    np.testing.assert_allclose(quat_to_euler_xyz(q), [a, b, c], atol=1e-12)
