"""Independent high-precision reference ("truth") for validating ``satenv.dynamics``.

Nothing here imports ``satenv``: every formula is re-derived and written from scratch so that a
mistake in the package cannot be mirrored by its reference.

Contents
--------
* Physical constants (same published values as the package's documented ones, typed in again).
* ``elements_to_rv``: classical orbital elements -> ECI state via perifocal frame and a 3-1-3
  rotation.
* Gravity: two-body, and J2 written as the gradient of the J2 zonal potential
  ``U_J2 = -(mu J2 Re^2 / 2) (3 z^2 / r^5 - 1 / r^3)`` (``j2_potential`` is kept so a test can
  check the acceleration against a complex-step derivative of the potential).
* ``propagate_eci``: one spacecraft in ECI with ``scipy.integrate.solve_ivp`` (DOP853,
  rtol 1e-12, atol 1e-6 m / 1e-9 m/s).
* LVLH conversion. The relative LVLH velocity is the exact time derivative of the LVLH
  components of the relative position, ``rho = R dr`` -> ``rho_dot = R_dot dr + R dv``, with
  ``R_dot`` obtained by differentiating the unit vectors of the chief frame directly
  (x = r/|r|, z = h/|h| with h_dot = r x a_chief, y = z x x). This equals the documented
  ``R (dv - omega x dr)`` with ``omega_z = |h|/r^2`` and ``omega_x = r (a . z_hat)/|h|``;
  ``omega_lvlh`` implements that second form so a test can check the two agree.
* ``truth_relative``: chief and each deputy propagated separately in ECI, then converted.
* ``truth_relative_encke``: a second, differently formulated truth (chief + ECI relative offset
  integrated as ``dr'' = g(r_c + dr) - g(r_c)``) used to check the first.
* ``truth_relative_thrust``: chief + deputies with an LVLH acceleration held constant in the
  rotating LVLH frame over each step (rotated with the chief's instantaneous frame inside the ODE).
* Clohessy-Wiltshire: ``cw_continuous_ref``, the textbook closed-form ``cw_stm_ref`` and the
  exact zero-order-hold ``cw_zoh_ref`` (matrix exponential of the augmented system).
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import expm

MU = 3.986004418e14  # m^3/s^2, EGM/WGS-84 GM of the Earth
RE = 6378137.0  # m, WGS-84 equatorial radius
J2 = 1.08262668e-3  # EGM-96 style unnormalised C20 (negated)

RTOL = 1e-12
ATOL_POS = 1e-6  # m
ATOL_VEL = 1e-9  # m/s
GRAVITY_MODELS = ("kepler", "j2")

# ----------------------------------------------------------------------------------------------
# Orbital elements
# ----------------------------------------------------------------------------------------------


def _rot1(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot3(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def elements_to_rv(
    a: float, e: float, i: float, raan: float, argp: float, nu: float, mu: float = MU
) -> np.ndarray:
    """Classical elements (SI, rad) -> ECI state ``[r, v]`` (6,)."""
    p = a * (1.0 - e * e)
    r_pf = p / (1.0 + e * np.cos(nu)) * np.array([np.cos(nu), np.sin(nu), 0.0])
    v_pf = np.sqrt(mu / p) * np.array([-np.sin(nu), e + np.cos(nu), 0.0])
    q = _rot3(raan) @ _rot1(i) @ _rot3(argp)  # perifocal -> ECI
    return np.concatenate([q @ r_pf, q @ v_pf])


def specific_energy_and_h(rv: np.ndarray, mu: float = MU) -> tuple[float, np.ndarray]:
    """Two-body specific energy and angular-momentum vector of an ECI state."""
    r, v = rv[:3], rv[3:]
    return float(v @ v / 2.0 - mu / np.linalg.norm(r)), np.cross(r, v)


# ----------------------------------------------------------------------------------------------
# Gravity
# ----------------------------------------------------------------------------------------------


def kepler_acc(r: np.ndarray, mu: float = MU) -> np.ndarray:
    """Point-mass gravity, r (..., 3)."""
    rn = np.linalg.norm(r, axis=-1, keepdims=True)
    return -mu * r / rn**3


def j2_potential(r: np.ndarray, mu: float = MU, re: float = RE, j2: float = J2) -> np.ndarray:
    """J2 part of the gravitational potential (sign: acceleration = +grad U). Works on complex r."""
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    r2 = x * x + y * y + z * z
    rr = np.sqrt(r2)
    return -0.5 * mu * j2 * re**2 * (3.0 * z * z / rr**5 - 1.0 / rr**3)


def j2_acc(r: np.ndarray, mu: float = MU, re: float = RE, j2: float = J2) -> np.ndarray:
    """grad of ``j2_potential`` written out by hand.

    d/dx(3 z^2 r^-5 - r^-3) = x (3 r^-5 - 15 z^2 r^-7)
    d/dz(3 z^2 r^-5 - r^-3) = z (9 r^-5 - 15 z^2 r^-7)
    """
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    r2 = x * x + y * y + z * z
    r5 = r2 * r2 * np.sqrt(r2)
    r7 = r5 * r2
    k = -0.5 * mu * j2 * re**2
    common = 3.0 / r5 - 15.0 * z * z / r7
    return k * np.stack([x * common, y * common, z * (9.0 / r5 - 15.0 * z * z / r7)], axis=-1)


def gravity_acc(r: np.ndarray, model: str) -> np.ndarray:
    """Total gravitational acceleration for ``model`` in ``GRAVITY_MODELS``."""
    if model == "kepler":
        return kepler_acc(r)
    if model == "j2":
        return kepler_acc(r) + j2_acc(r)
    raise ValueError(f"truth gravity model {model!r} unknown; expected one of {GRAVITY_MODELS}")


# ----------------------------------------------------------------------------------------------
# ECI propagation
# ----------------------------------------------------------------------------------------------


def _atol(n_bodies: int) -> np.ndarray:
    return np.tile(np.r_[np.full(3, ATOL_POS), np.full(3, ATOL_VEL)], n_bodies)


def propagate_eci(rv0: np.ndarray, t_eval: np.ndarray, model: str) -> np.ndarray:
    """Propagate one spacecraft; returns (len(t_eval), 6) ECI states."""

    def rhs(_t: float, s: np.ndarray) -> np.ndarray:
        return np.concatenate([s[3:], gravity_acc(s[:3], model)])

    sol = solve_ivp(
        rhs, (t_eval[0], t_eval[-1]), np.asarray(rv0, float), method="DOP853",
        t_eval=t_eval, rtol=RTOL, atol=_atol(1),
    )
    if not sol.success:
        raise RuntimeError(f"truth propagation failed: {sol.message}")
    return sol.y.T


# ----------------------------------------------------------------------------------------------
# LVLH frame
# ----------------------------------------------------------------------------------------------


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _unit_dot(v: np.ndarray, vdot: np.ndarray) -> np.ndarray:
    """d/dt (v/|v|) = (vdot - u (u . vdot)) / |v|."""
    u = _unit(v)
    return (vdot - u * np.sum(u * vdot, axis=-1, keepdims=True)) / np.linalg.norm(
        v, axis=-1, keepdims=True
    )


def lvlh_frame(chief_rv: np.ndarray, chief_acc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R (rows = LVLH axes in ECI) and its exact time derivative, both (..., 3, 3)."""
    r, v = chief_rv[..., :3], chief_rv[..., 3:]
    h = np.cross(r, v)
    hdot = np.cross(r, chief_acc)  # d/dt (r x v) = v x v + r x a
    xh, zh = _unit(r), _unit(h)
    xd, zd = _unit_dot(r, v), _unit_dot(h, hdot)
    yh = np.cross(zh, xh)
    yd = np.cross(zd, xh) + np.cross(zh, xd)
    return np.stack([xh, yh, zh], axis=-2), np.stack([xd, yd, zd], axis=-2)


def omega_lvlh(chief_rv: np.ndarray, chief_acc: np.ndarray) -> np.ndarray:
    """Angular velocity of the LVLH frame in ECI, documented form omega_x x_hat + omega_z z_hat."""
    r, v = chief_rv[..., :3], chief_rv[..., 3:]
    h = np.cross(r, v)
    rn = np.linalg.norm(r, axis=-1, keepdims=True)
    hn = np.linalg.norm(h, axis=-1, keepdims=True)
    zh = h / hn
    om_x = rn * np.sum(chief_acc * zh, axis=-1, keepdims=True) / hn
    om_z = hn / rn**2
    return om_x * (r / rn) + om_z * zh


def eci_to_lvlh(chief_rv: np.ndarray, chief_acc: np.ndarray, deputy_rv: np.ndarray) -> np.ndarray:
    """chief (...,6), acc (...,3), deputies (..., M, 6) -> LVLH (..., M, 6)."""
    rot, rdot = lvlh_frame(chief_rv, chief_acc)
    dr = deputy_rv[..., :3] - chief_rv[..., None, :3]
    dv = deputy_rv[..., 3:] - chief_rv[..., None, 3:]
    rho = np.einsum("...ij,...mj->...mi", rot, dr)
    rho_dot = np.einsum("...ij,...mj->...mi", rdot, dr) + np.einsum("...ij,...mj->...mi", rot, dv)
    return np.concatenate([rho, rho_dot], axis=-1)


def lvlh_to_eci(chief_rv: np.ndarray, chief_acc: np.ndarray, x_lvlh: np.ndarray) -> np.ndarray:
    """Inverse of ``eci_to_lvlh``: dr = R^T rho, dv = R^T (rho_dot - R_dot dr)."""
    rot, rdot = lvlh_frame(chief_rv, chief_acc)
    dr = np.einsum("...ji,...mj->...mi", rot, x_lvlh[..., :3])
    tmp = x_lvlh[..., 3:] - np.einsum("...ij,...mj->...mi", rdot, dr)
    dv = np.einsum("...ji,...mj->...mi", rot, tmp)
    return np.concatenate([chief_rv[..., None, :3] + dr, chief_rv[..., None, 3:] + dv], axis=-1)


# ----------------------------------------------------------------------------------------------
# Relative-motion truths
# ----------------------------------------------------------------------------------------------


def truth_relative(model: str, x0: np.ndarray, chief_rv0: np.ndarray, t_eval: np.ndarray) -> np.ndarray:
    """Each spacecraft propagated separately in ECI; returns LVLH states (len(t), M, 6)."""
    x0 = np.atleast_2d(np.asarray(x0, float))
    chief_rv0 = np.asarray(chief_rv0, float)
    acc0 = gravity_acc(chief_rv0[:3], model)
    dep0 = lvlh_to_eci(chief_rv0, acc0, x0)
    chief = propagate_eci(chief_rv0, t_eval, model)
    deps = np.stack([propagate_eci(d, t_eval, model) for d in dep0], axis=1)
    return eci_to_lvlh(chief, gravity_acc(chief[:, :3], model), deps)


def truth_relative_encke(
    model: str, x0: np.ndarray, chief_rv0: np.ndarray, t_eval: np.ndarray
) -> np.ndarray:
    """Second truth: chief plus ECI offsets dr integrated as dr'' = g(r_c + dr) - g(r_c)."""
    x0 = np.atleast_2d(np.asarray(x0, float))
    m = x0.shape[0]
    chief_rv0 = np.asarray(chief_rv0, float)
    acc0 = gravity_acc(chief_rv0[:3], model)
    off0 = lvlh_to_eci(chief_rv0, acc0, x0) - chief_rv0[None, :]

    def rhs(_t: float, s: np.ndarray) -> np.ndarray:
        c = s[:6]
        d = s[6:].reshape(m, 6)
        gc = gravity_acc(c[:3], model)
        gd = gravity_acc(c[None, :3] + d[:, :3], model) - gc[None, :]
        return np.concatenate([c[3:], gc, np.concatenate([d[:, 3:], gd], axis=1).ravel()])

    atol = np.r_[_atol(1), np.tile(np.r_[np.full(3, 1e-9), np.full(3, 1e-12)], m)]
    sol = solve_ivp(
        rhs, (t_eval[0], t_eval[-1]), np.r_[chief_rv0, off0.ravel()], method="DOP853",
        t_eval=t_eval, rtol=RTOL, atol=atol,
    )
    if not sol.success:
        raise RuntimeError(f"truth propagation failed: {sol.message}")
    y = sol.y.T
    chief = y[:, :6]
    deps = chief[:, None, :] + y[:, 6:].reshape(len(t_eval), m, 6)
    return eci_to_lvlh(chief, gravity_acc(chief[:, :3], model), deps)


def truth_relative_thrust(
    model: str, x0: np.ndarray, chief_rv0: np.ndarray, dt: float, u: np.ndarray
) -> np.ndarray:
    """Deputies with LVLH acceleration ``u`` (steps, M, 3) held constant in the rotating LVLH
    frame over each step (ECI thrust = R(t)^T u_k with R(t) the chief's instantaneous frame).
    Chief and deputies integrated jointly, one solve_ivp per step. Returns (steps+1, M, 6)."""
    x0 = np.atleast_2d(np.asarray(x0, float))
    m = x0.shape[0]
    chief_rv0 = np.asarray(chief_rv0, float)
    acc0 = gravity_acc(chief_rv0[:3], model)
    s = np.r_[chief_rv0, lvlh_to_eci(chief_rv0, acc0, x0).ravel()]
    atol = _atol(m + 1)
    out = [s.copy()]
    for k in range(u.shape[0]):
        uk = np.asarray(u[k], float)

        def rhs(_t: float, y: np.ndarray, uk: np.ndarray = uk) -> np.ndarray:
            b = y.reshape(m + 1, 6)
            c = b[0]
            rot, _ = lvlh_frame(c, gravity_acc(c[:3], model))
            acc = gravity_acc(b[:, :3], model)
            acc[1:] += uk @ rot  # R^T u per deputy
            return np.concatenate([b[:, 3:], acc], axis=1).ravel()

        sol = solve_ivp(rhs, (k * dt, (k + 1) * dt), s, method="DOP853", rtol=RTOL, atol=atol)
        if not sol.success:
            raise RuntimeError(f"truth propagation failed: {sol.message}")
        s = sol.y[:, -1]
        out.append(s.copy())
    y = np.array(out).reshape(len(out), m + 1, 6)
    chief = y[:, 0]
    return eci_to_lvlh(chief, gravity_acc(chief[:, :3], model), y[:, 1:])


# ----------------------------------------------------------------------------------------------
# Clohessy-Wiltshire references
# ----------------------------------------------------------------------------------------------


def cw_continuous_ref(n: float) -> tuple[np.ndarray, np.ndarray]:
    """x'' = 3n^2 x + 2n y' + ux, y'' = -2n x' + uy, z'' = -n^2 z + uz."""
    a = np.zeros((6, 6))
    a[0:3, 3:6] = np.eye(3)
    a[3, 0], a[3, 4] = 3.0 * n * n, 2.0 * n
    a[4, 3] = -2.0 * n
    a[5, 2] = -n * n
    b = np.zeros((6, 3))
    b[3:, :] = np.eye(3)
    return a, b


def cw_stm_ref(n: float, t: float) -> np.ndarray:
    """Textbook closed-form CW state-transition matrix (x radial, y along-track, z normal)."""
    s, c, nt = np.sin(n * t), np.cos(n * t), n * t
    return np.array(
        [
            [4 - 3 * c, 0, 0, s / n, 2 * (1 - c) / n, 0],
            [6 * (s - nt), 1, 0, -2 * (1 - c) / n, (4 * s - 3 * nt) / n, 0],
            [0, 0, c, 0, 0, s / n],
            [3 * n * s, 0, 0, c, 2 * s, 0],
            [-6 * n * (1 - c), 0, 0, -2 * s, 4 * c - 3, 0],
            [0, 0, -n * s, 0, 0, c],
        ]
    )


def cw_zoh_ref(n: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretisation via expm([[A_c, B_c], [0, 0]] dt) = [[A, B], [0, I]]."""
    a, b = cw_continuous_ref(n)
    aug = np.zeros((9, 9))
    aug[:6, :6], aug[:6, 6:] = a, b
    e = expm(aug * dt)
    return e[:6, :6], e[:6, 6:]
