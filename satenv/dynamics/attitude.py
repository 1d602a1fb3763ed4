"""Relative attitude of a spacecraft w.r.t. the LVLH-aligned object frame (pereira2022 §2.3, §4).

Pure, batch-first numpy functions: quaternions ``(..., 4)`` scalar first ``[eta, eps]``,
vectors ``(..., 3)``, matrices ``(..., 3, 3)``; SI units (rad, rad/s, kg m^2, N m).

Conventions (one self-consistent set; the paper's labels are ambiguous):

* Hamilton product (eq. 8). The relative attitude ``q`` of the follower body frame F_fb w.r.t.
  the leader body frame F_lb obeys eq. 10, ``q_dot = 1/2 [-eps^T; eta I + S(eps)] omega``
  ``= 1/2 q (x) [0, omega]`` with ``omega`` the relative angular velocity in F_fb.
* With that kinematics, ``R(q) = I + 2 eta S(eps) + 2 S(eps)^2`` (the formula of eq. 17) maps
  follower-body components to leader-body (= LVLH) components, i.e. it is ``R^lb_fb``; the
  paper labels the formula ``R^fb_lb``. We use ``R^fb_lb = R(q)^T`` wherever eq. 12-16 need the
  rotation from F_lb to F_fb (a transposition only: the physics below is derived from Euler's
  equations and checked against them in the tests).
* The pointing (boresight) axis is the body z axis: with ``q = q_d`` it coincides with the
  desired frame's ``k_d`` which points at the target (eq. 44).
"""

from __future__ import annotations

import numpy as np

from .integrators import rk4_step

__all__ = [
    "ATTITUDE_METHODS", "attitude_constants", "attitude_derivative", "attitude_kernel", "attitude_step",
    "compiled_attitude_step", "desired_angular_velocity", "matrix_to_quat",
    "pointing_error", "pointing_frame", "pointing_rate", "quat_conjugate", "quat_error",
    "quat_kinematics", "quat_multiply", "quat_normalize", "quat_to_euler_xyz", "quat_to_matrix",
    "relative_angular_acceleration", "skew", "thruster_matrices",
]


def skew(v: np.ndarray) -> np.ndarray:
    """Skew-symmetric cross-product matrix ``S(v)`` (eq. 9): ``S(a) b = a x b``; (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([np.stack([z, -w, y], -1), np.stack([w, z, -x], -1),
                     np.stack([-y, x, z], -1)], -2)


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a (x) b`` of scalar-first quaternions (..., 4)."""
    ea, va = a[..., :1], a[..., 1:]
    eb, vb = b[..., :1], b[..., 1:]
    eta = ea * eb - np.sum(va * vb, axis=-1, keepdims=True)
    vec = ea * vb + eb * va + np.cross(va, vb)
    return np.concatenate([eta, vec], axis=-1)


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """``q_bar = [eta, -eps]``."""
    return np.concatenate([q[..., :1], -q[..., 1:]], axis=-1)


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Project quaternions back onto the unit sphere (the integrator calls this every step).

    Raises ``ValueError`` for a (numerically) zero quaternion, which has no attitude.
    """
    q = np.asarray(q, dtype=float)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm < 1e-12):
        raise ValueError("cannot normalise a zero quaternion; a unit quaternion [eta, ex, ey, ez] "
                         f"is needed (got norms {norm.min():.3g})")
    return q / norm


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """``R(q) = I + 2 eta S(eps) + 2 S(eps)^2`` (eq. 17 formula): body -> reference (..., 3, 3)."""
    s = skew(q[..., 1:])
    return np.eye(3) + 2.0 * q[..., 0, None, None] * s + 2.0 * s @ s


def matrix_to_quat(r: np.ndarray) -> np.ndarray:
    """Unit quaternion (eta >= 0) with ``quat_to_matrix(q) == r`` for rotation matrices (..., 3, 3).

    Shepperd's method (the largest of the four squared components is taken first).
    """
    r = np.asarray(r, dtype=float)
    tr = np.trace(r, axis1=-2, axis2=-1)
    d = np.stack([tr, r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]], axis=-1)
    k = np.argmax(d, axis=-1)
    q = np.empty((*r.shape[:-2], 4))
    r21m, r02m, r10m = r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]
    r21p, r02p, r10p = r[..., 2, 1] + r[..., 1, 2], r[..., 0, 2] + r[..., 2, 0], r[..., 1, 0] + r[..., 0, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        s0 = 2.0 * np.sqrt(np.maximum(1.0 + tr, 0.0))
        c0 = np.stack([s0 / 4, r21m / s0, r02m / s0, r10m / s0], -1)
        s1 = 2.0 * np.sqrt(np.maximum(1.0 + 2 * r[..., 0, 0] - tr, 0.0))
        c1 = np.stack([r21m / s1, s1 / 4, r10p / s1, r02p / s1], -1)
        s2 = 2.0 * np.sqrt(np.maximum(1.0 + 2 * r[..., 1, 1] - tr, 0.0))
        c2 = np.stack([r02m / s2, r10p / s2, s2 / 4, r21p / s2], -1)
        s3 = 2.0 * np.sqrt(np.maximum(1.0 + 2 * r[..., 2, 2] - tr, 0.0))
        c3 = np.stack([r10m / s3, r02p / s3, r21p / s3, s3 / 4], -1)
    for i, c in enumerate((c0, c1, c2, c3)):
        sel = k == i
        q[sel] = c[sel]
    q = q * np.where(q[..., :1] < 0, -1.0, 1.0)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_error(q: np.ndarray, q_d: np.ndarray) -> np.ndarray:
    """Quaternion error ``q_tilde = q (x) q_d_bar`` (§4.4), sign chosen so that ``eta_tilde >= 0``."""
    e = quat_multiply(q, quat_conjugate(q_d))
    return e * np.where(e[..., :1] < 0, -1.0, 1.0)


def quat_kinematics(q: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Eq. 10: ``q_dot = 1/2 [-eps^T omega; (eta I + S(eps)) omega]`` (omega in the body frame)."""
    eta, eps = q[..., :1], q[..., 1:]
    return 0.5 * np.concatenate([-np.sum(eps * omega, axis=-1, keepdims=True),
                                 eta * omega + np.cross(eps, omega)], axis=-1)


def _mv(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("...ij,...j->...i", m, v)


def relative_angular_acceleration(q: np.ndarray, omega: np.ndarray, torque: np.ndarray,
                                  j_f: np.ndarray, j_l: np.ndarray, omega_l: np.ndarray,
                                  torque_l: np.ndarray | None = None) -> np.ndarray:
    """Eq. 13-16: ``omega_dot = J_f^-1 (C_r omega + E_r + T_r)``.

    Args:
        q, omega: relative attitude (..., 4) and relative angular velocity in F_fb (..., 3).
        torque: follower actuator torque in F_fb (..., 3) [N m].
        j_f, j_l: follower / leader inertia (3, 3) [kg m^2].
        omega_l: the leader body's inertial angular velocity in F_lb (3,) or (..., 3); for the
            LVLH-fixed object of §4, ``[0, 0, n]``.
        torque_l: leader torque in F_lb (default: passive leader, zero).
    """
    r_fl = np.swapaxes(quat_to_matrix(q), -1, -2)        # R^fb_lb
    wl = np.broadcast_to(np.asarray(omega_l, dtype=float), omega.shape)
    w_lf = _mv(r_fl, wl)                                  # R^fb_lb omega_l
    j_f = np.asarray(j_f, dtype=float)
    j_l = np.asarray(j_l, dtype=float)
    j_l_inv = np.linalg.inv(j_l)
    c_r = -j_f @ skew(w_lf) - skew(w_lf) @ j_f + skew(_mv(j_f, omega + w_lf))       # eq. 14
    lead_acc = _mv(j_l_inv, np.cross(wl, _mv(j_l, wl)))                               # J_l^-1 S(w_l) J_l w_l
    e_r = -np.cross(w_lf, _mv(j_f, w_lf)) + _mv(j_f, _mv(r_fl, lead_acc))             # eq. 15
    t_r = torque
    if torque_l is not None:                                                          # eq. 16
        t_r = torque - _mv(j_f, _mv(r_fl, _mv(j_l_inv, np.broadcast_to(torque_l, omega.shape))))
    return np.linalg.solve(j_f, (_mv(c_r, omega) + e_r + t_r)[..., None])[..., 0]


def attitude_derivative(y: np.ndarray, torque: np.ndarray, j_f: np.ndarray, j_l: np.ndarray,
                        omega_l: np.ndarray) -> np.ndarray:
    """Time derivative of the packed attitude state ``y = [q (4), omega (3)]`` (..., 7)."""
    q, w = y[..., :4], y[..., 4:]
    return np.concatenate([quat_kinematics(q, w),
                           relative_angular_acceleration(q, w, torque, j_f, j_l, omega_l)], axis=-1)


ATTITUDE_METHODS: tuple[str, ...] = ("auto", "kernel", "numpy")
"""Implementations of :func:`attitude_step`: ``"numpy"`` (the reference), ``"kernel"`` (compiled,
:mod:`._attitude_kernel`; needs numba and a constant leader rate ``omega_l`` (3,)), ``"auto"``."""


def attitude_step(q: np.ndarray, omega: np.ndarray, torque: np.ndarray, dt: float, j_f: np.ndarray,
                  j_l: np.ndarray, omega_l: np.ndarray, substeps: int = 1,
                  method: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """Advance ``(q, omega)`` by ``dt`` under a constant body torque: RK4, then renormalise ``q``.

    ``substeps`` RK4 steps of ``dt / substeps``; ``q`` is projected back to unit norm after each.
    ``method`` (:data:`ATTITUDE_METHODS`): the compiled kernel gives the numpy reference's
    answers to rounding (1e-12, ``tests/test_attitude_kernel.py``).
    """
    if method not in ATTITUDE_METHODS:
        raise ValueError(f"unknown attitude method {method!r}; expected one of {list(ATTITUDE_METHODS)}")
    kernel = None if method == "numpy" else attitude_kernel(method, omega_l)
    if kernel is not None:
        return compiled_attitude_step(kernel, q, omega, torque, dt, substeps,
                                      attitude_constants(j_f, j_l, omega_l))
    y = np.concatenate([q, omega], axis=-1)
    h = dt / substeps
    f = lambda _t, yy: attitude_derivative(yy, torque, j_f, j_l, omega_l)  # noqa: E731
    for _ in range(substeps):
        y = rk4_step(f, 0.0, y, h)
        y = np.concatenate([quat_normalize(y[..., :4]), y[..., 4:]], axis=-1)
    return y[..., :4], y[..., 4:]


def attitude_kernel(method: str, omega_l):
    """The compiled step, or ``None`` when it does not apply (``method="auto"``)."""
    if np.shape(omega_l) != (3,):
        if method == "kernel":
            raise ValueError(f"method='kernel' needs a constant leader rate omega_l of shape (3,), "
                             f"got shape {np.shape(omega_l)}")
        return None
    try:
        from ._attitude_kernel import attitude_steps
    except ImportError:
        if method == "kernel":
            raise ValueError("method='kernel' needs numba (pip install numba)") from None
        return None
    return attitude_steps


def attitude_constants(j_f, j_l, omega_l) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(J_f, J_f^-1, omega_l, J_l^-1 (omega_l x J_l omega_l))``: the compiled step's constants."""
    j_f = np.ascontiguousarray(j_f, dtype=float)
    j_l = np.asarray(j_l, dtype=float)
    wl = np.ascontiguousarray(omega_l, dtype=float)
    lead_acc = _mv(np.linalg.inv(j_l), np.cross(wl, _mv(j_l, wl)))
    return j_f, np.linalg.inv(j_f), wl, np.ascontiguousarray(lead_acc)


def compiled_attitude_step(kernel, q, omega, torque, dt: float, substeps: int,
                           constants) -> tuple[np.ndarray, np.ndarray]:
    """:func:`attitude_step` by the compiled ``kernel`` with :func:`attitude_constants`."""
    shape = np.broadcast_shapes(np.shape(q)[:-1], np.shape(omega)[:-1], np.shape(torque)[:-1])
    qs = np.ascontiguousarray(np.broadcast_to(q, (*shape, 4)).reshape(-1, 4), dtype=float)
    ws = np.ascontiguousarray(np.broadcast_to(omega, (*shape, 3)).reshape(-1, 3), dtype=float)
    ts = np.ascontiguousarray(np.broadcast_to(torque, (*shape, 3)).reshape(-1, 3), dtype=float)
    q_out, w_out = np.empty_like(qs), np.empty_like(ws)
    kernel(qs, ws, ts, dt / substeps, substeps, *constants, q_out, w_out)
    if np.isnan(q_out).any() and np.isfinite(qs).all() and np.isfinite(ws).all() and np.isfinite(ts).all():
        raise ValueError("cannot normalise a zero quaternion; a unit quaternion [eta, ex, ey, ez] "
                         "is needed (the attitude step reached a zero-norm quaternion)")
    return q_out.reshape(*shape, 4), w_out.reshape(*shape, 3)


def thruster_matrices(dimensions) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 36: the thruster configuration matrices ``(F_t (3, 6), F_r (3, 6))``.

    ``F_t u`` is the translational acceleration (per unit mass) and ``F_r u`` the body torque of
    the six inputs ``u``; ``dimensions = [L_x, L_y, L_z]`` [m]. Column i of ``F_r`` is
    ``r_i x F_t[:, i]`` for thrusters mounted at ``r_1 = (Lx, Ly, .)/2``, ``r_2 = -(Lx, Ly, .)/2``,
    ``r_3 = (., Ly, Lz)/2``, ``r_4 = -(., Ly, Lz)/2``, ``r_5 = (Lx, ., -Lz)/2``,
    ``r_6 = (-Lx, ., Lz)/2``.
    """
    lx, ly, lz = (float(v) for v in np.asarray(dimensions, dtype=float).reshape(3))
    f_t = np.array([[0, 0, 1, -1, 0, 0],
                    [0, 0, 0, 0, 1, -1],
                    [1, -1, 0, 0, 0, 0]], dtype=float)
    f_r = 0.5 * np.array([[ly, ly, 0, 0, lz, lz],
                          [-lx, -lx, lz, lz, 0, 0],
                          [0, 0, -ly, -ly, lx, lx]], dtype=float)
    return f_t, f_r


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-300), n[..., 0]


def pointing_frame(p: np.ndarray, target=(0.0, 0.0, 0.0), reference=None,
                   min_sine: float = 0.1) -> np.ndarray:
    """Eq. 43-44: the desired frame ``R_d = [i_d j_d k_d]`` (columns in LVLH), (..., 3, 3).

    ``k_d = (t - p) / |t - p|`` points from the spacecraft at ``p`` to the target point ``t``
    (eq. 43 with ``R^fo_lo ~ I``, eq. 47's approximation); ``j_d = k_d x a / |k_d x a|``,
    ``i_d = j_d x k_d``. Eq. 44 uses ``a = p`` (``reference=None``), which is degenerate when the
    target is the object's centre (``k_d`` is then parallel to ``p``): pass a fixed
    ``reference`` direction instead. Where ``|k_d x a| < min_sine`` (``a`` nearly parallel to
    ``k_d``) the LVLH axis least aligned with ``k_d`` is used as ``a`` (a discontinuity in roll
    about the pointing axis only). ``R_d`` is the rotation from F_d to LVLH, so the desired
    quaternion is ``matrix_to_quat(R_d)``.
    """
    p = np.asarray(p, dtype=float)
    k, dist = _unit(np.asarray(target, dtype=float) - p)
    if np.any(dist < 1e-9):
        raise ValueError("pointing_frame: the spacecraft position coincides with the target point; "
                         "the pointing direction is undefined")
    a = p if reference is None else np.broadcast_to(np.asarray(reference, dtype=float), p.shape)
    c = np.cross(k, a)
    cn = np.linalg.norm(c, axis=-1) / np.maximum(np.linalg.norm(a, axis=-1), 1e-300)
    bad = cn < min_sine
    if np.any(bad):
        axis = np.eye(3)[np.argmin(np.abs(k), axis=-1)]
        c = np.where(bad[..., None], np.cross(k, axis), c)
    j, _ = _unit(c)
    i = np.cross(j, k)
    return np.stack([i, j, k], axis=-1)


def pointing_rate(p: np.ndarray, v: np.ndarray, r_d: np.ndarray, target=(0.0, 0.0, 0.0),
                  target_rate=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Eq. 45-47: ``omega^d_fo,d = [-t_dot . j_d, t_dot . i_d, 0] / |t|`` in F_d components.

    ``t = target - p``, ``t_dot = target_rate - v`` (eq. 47, ``R^fo_lo ~ I``, ``omega_fo,lo ~ 0``).
    """
    t = np.asarray(target, dtype=float) - p
    t_dot = np.asarray(target_rate, dtype=float) - v
    tn = np.linalg.norm(t, axis=-1)
    i_d, j_d = r_d[..., :, 0], r_d[..., :, 1]
    return np.stack([-np.sum(t_dot * j_d, -1) / tn, np.sum(t_dot * i_d, -1) / tn,
                     np.zeros_like(tn)], axis=-1)


def desired_angular_velocity(q: np.ndarray, r_d: np.ndarray, w_d: np.ndarray, n_l: float,
                             n_f: float | None = None) -> np.ndarray:
    """Eq. 49: desired relative angular velocity in F_fb,
    ``-R^fb_lb [0,0,n_l] + R^fb_fo ([0,0,n_f] + R^fo_d w_d)`` with ``F_fo`` parallel to ``F_lo``.
    """
    r_fl = np.swapaxes(quat_to_matrix(q), -1, -2)
    n_f = n_l if n_f is None else n_f
    inner = np.array([0.0, 0.0, n_f]) + _mv(r_d, w_d) - np.array([0.0, 0.0, n_l])
    return _mv(r_fl, inner)


def pointing_error(q: np.ndarray, p: np.ndarray, target=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Angle [rad] between the body z (boresight) axis and the line of sight to ``target``."""
    bore = quat_to_matrix(q)[..., :, 2]
    los, _ = _unit(np.asarray(target, dtype=float) - p)
    return np.arccos(np.clip(np.sum(bore * los, axis=-1), -1.0, 1.0))


def quat_to_euler_xyz(q: np.ndarray) -> np.ndarray:
    """Euler angles [rad] (..., 3) of the XYZ sequence: ``R(q) = R_x(a) R_y(b) R_z(c)``."""
    r = quat_to_matrix(q)
    b = np.arcsin(np.clip(r[..., 0, 2], -1.0, 1.0))
    a = np.arctan2(-r[..., 1, 2], r[..., 2, 2])
    c = np.arctan2(-r[..., 0, 1], r[..., 0, 0])
    return np.stack([a, b, c], axis=-1)
