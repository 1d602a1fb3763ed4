"""Chief orbit, orbital elements <-> ECI, and ECI <-> LVLH (Hill) frame conversions.

LVLH axes: x radial (R-bar), y along-track (V-bar), z orbit normal (H-bar, along r x v).
The LVLH relative velocity is the time derivative of the LVLH components of the relative
position: ``rho_dot = R (dv - omega x dr)`` with the frame's angular velocity
``omega = omega_x x_hat + omega_z z_hat``, ``omega_z = |h| / r^2`` and
``omega_x = r (a . z_hat) / |h|`` where ``a`` is the chief's acceleration (``omega_x`` is zero
for a Keplerian chief and carries the out-of-plane J2 term otherwise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from satenv.errors import SatenvError

from ._checks import as_array, derived, real
from ._soa import eci_rel_to_lvlh_soa, frame_rate_soa, lvlh_axes, lvlh_to_eci_rel_soa
from .constants import MU_EARTH, R_EARTH


@dataclass(frozen=True)
class Orbit:
    """Classical orbital elements of the chief (SI units, angles in radians).

    Args:
        a: semi-major axis [m], must exceed Earth's radius.
        e: eccentricity, 0 <= e < 1.
        i: inclination [rad], 0 <= i <= pi.
        raan: right ascension of the ascending node [rad].
        argp: argument of perigee [rad].
        nu: true anomaly at epoch [rad].
        mu: gravitational parameter [m^3/s^2].
    """

    a: float
    e: float = 0.0
    i: float = 0.0
    raan: float = 0.0
    argp: float = 0.0
    nu: float = 0.0
    mu: float = MU_EARTH

    def __post_init__(self) -> None:
        for name in ("a", "e", "i", "raan", "argp", "nu", "mu"):
            object.__setattr__(self, name, real(getattr(self, name), f"Orbit.{name}"))
        if self.mu <= 0:
            raise SatenvError(f"Orbit.mu must be > 0, got {self.mu!r}")
        if not 0.0 <= self.e < 1.0:
            raise SatenvError(f"Orbit.e must satisfy 0 <= e < 1 (closed orbit), got {self.e!r}")
        if not 0.0 <= self.i <= math.pi:
            raise SatenvError(f"Orbit.i must be in [0, pi] rad, got {self.i!r} "
                              "(angles are in radians: use math.radians)")
        perigee = self.a * (1.0 - self.e)
        if perigee <= R_EARTH:
            raise SatenvError(f"Orbit perigee radius a(1-e) = {perigee:.1f} m is inside the Earth "
                              f"(R = {R_EARTH:.0f} m); got a={self.a!r}, e={self.e!r}. "
                              "Give a in metres, e.g. Orbit(a=6878e3)")
        inputs = f"a = {self.a!r} m, mu = {self.mu!r}"
        derived(lambda: self.n, "Orbit: the mean motion sqrt(mu / a^3)", inputs)
        derived(lambda: self.period, "Orbit: the period 2 pi / n", inputs)

    @classmethod
    def circular(cls, radius: float, i: float = 0.0, raan: float = 0.0, u: float = 0.0,
                 mu: float = MU_EARTH) -> Orbit:
        """A circular orbit of the given radius [m]; ``u`` is the argument of latitude [rad]."""
        return cls(a=radius, e=0.0, i=i, raan=raan, argp=0.0, nu=u, mu=mu)

    @property
    def n(self) -> float:
        """Mean motion [rad/s]."""
        return math.sqrt(self.mu / self.a**3)

    @property
    def period(self) -> float:
        """Orbital period [s]."""
        return 2.0 * math.pi / self.n

    @property
    def rv(self) -> np.ndarray:
        """ECI state ``[r, v]`` (6,) at epoch."""
        return elements_to_rv(self.a, self.e, self.i, self.raan, self.argp, self.nu, self.mu)


def elements_to_rv(a: float, e: float, i: float, raan: float, argp: float, nu: float,
                   mu: float = MU_EARTH) -> np.ndarray:
    """Classical orbital elements -> ECI state ``[r, v]`` (6,)."""
    p = a * (1.0 - e * e)
    r = p / (1.0 + e * math.cos(nu))
    r_pf = np.array([r * math.cos(nu), r * math.sin(nu), 0.0])
    v_pf = math.sqrt(mu / p) * np.array([-math.sin(nu), e + math.cos(nu), 0.0])
    cO, sO, ci, si, cw, sw = (math.cos(raan), math.sin(raan), math.cos(i), math.sin(i),
                              math.cos(argp), math.sin(argp))
    rot = np.array([
        [cO * cw - sO * sw * ci, -cO * sw - sO * cw * ci, sO * si],
        [sO * cw + cO * sw * ci, -sO * sw + cO * cw * ci, -cO * si],
        [sw * si, cw * si, ci],
    ])
    return np.concatenate([rot @ r_pf, rot @ v_pf])


def rv_to_elements(rv, mu: float = MU_EARTH) -> Orbit:
    """ECI state (6,) -> :class:`Orbit` (osculating elements; bound orbits only)."""
    rv = as_array(rv, "rv", (6,))
    if rv.ndim != 1:
        raise ValueError(f"rv must have shape (6,), got {rv.shape}")
    r, v = rv[:3], rv[3:]
    rn = np.linalg.norm(r)
    h = np.cross(r, v)
    hn = np.linalg.norm(h)
    node = np.cross([0.0, 0.0, 1.0], h)
    nn = np.linalg.norm(node)
    ev = np.cross(v, h) / mu - r / rn
    e = float(np.linalg.norm(ev))
    energy = v @ v / 2.0 - mu / rn
    if energy >= 0:
        raise ValueError(f"rv describes an unbound orbit (specific energy {energy:.3g} >= 0)")
    a = -mu / (2.0 * energy)
    i = math.acos(np.clip(h[2] / hn, -1.0, 1.0))
    tol = 1e-11
    raan = math.atan2(node[1], node[0]) % (2 * math.pi) if nn > tol * hn else 0.0
    # Reference direction for argp/nu: the node line (or x axis for equatorial orbits).
    ref = node / nn if nn > tol * hn else np.array([1.0, 0.0, 0.0])
    hhat = h / hn
    def angle(vec: np.ndarray) -> float:
        return math.atan2(hhat @ np.cross(ref, vec), ref @ vec) % (2 * math.pi)
    if e > tol:
        argp = angle(ev)
        nu = (angle(r) - argp) % (2 * math.pi)
    else:
        argp, nu = 0.0, angle(r)
    return Orbit(a=a, e=e, i=i, raan=raan, argp=argp, nu=nu, mu=mu)


def lvlh_rotation(chief_rv) -> np.ndarray:
    """Rotation (..., 3, 3) from ECI to LVLH: its rows are the LVLH axes in ECI."""
    chief_rv = as_array(chief_rv, "chief_rv", (6,))
    return _rotation(chief_rv[..., :3], chief_rv[..., 3:])


def _rotation(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """ECI -> LVLH rotation (..., 3, 3) of chief position/velocity (..., 3)."""
    ex, ey, ez, _ = lvlh_axes(np.moveaxis(r, -1, 0), np.moveaxis(v, -1, 0))
    return np.stack([np.moveaxis(ex, 0, -1), np.moveaxis(ey, 0, -1), np.moveaxis(ez, 0, -1)], axis=-2)


def frame_rate(chief_rv: np.ndarray, chief_acc: np.ndarray | None = None) -> np.ndarray:
    """LVLH angular velocity (..., 3) expressed in LVLH components ``[omega_x, 0, omega_z]``."""
    r, v = np.moveaxis(chief_rv[..., :3], -1, 0), np.moveaxis(chief_rv[..., 3:], -1, 0)
    acc = None if chief_acc is None else np.moveaxis(chief_acc, -1, 0)
    wx, wz = frame_rate_soa(r, lvlh_axes(r, v)[3], acc)
    return np.stack([wx, np.zeros_like(wz), wz], axis=-1)


def eci_to_lvlh(chief_rv, deputy_rv, chief_acc=None) -> np.ndarray:
    """Deputies' ECI states (..., M, 6) -> LVLH relative states (..., M, 6).

    ``chief_rv`` is (..., 6); ``chief_acc`` (..., 3) is the chief's ECI acceleration, needed only
    when it has an out-of-plane component (J2, drag); ``None`` means a Keplerian chief.
    """
    chief_rv = as_array(chief_rv, "chief_rv", (6,))
    deputy_rv = as_array(deputy_rv, "deputy_rv", (6,), min_ndim=2)
    acc = None if chief_acc is None else as_array(chief_acc, "chief_acc", (3,))
    return _eci_to_lvlh(chief_rv, deputy_rv - chief_rv[..., None, :], acc)


def lvlh_to_eci(chief_rv, x_lvlh, chief_acc=None) -> np.ndarray:
    """LVLH relative states (..., M, 6) -> deputies' ECI states (..., M, 6)."""
    chief_rv = as_array(chief_rv, "chief_rv", (6,))
    x_lvlh = as_array(x_lvlh, "x_lvlh", (6,), min_ndim=2)
    acc = None if chief_acc is None else as_array(chief_acc, "chief_acc", (3,))
    return chief_rv[..., None, :] + _lvlh_to_eci_rel(chief_rv, x_lvlh, acc)


def _to_soa(x: np.ndarray) -> np.ndarray:
    """(..., M, 6) -> component-major (6, M, ...)."""
    return np.moveaxis(x, (-1, -2), (0, 1))


def _from_soa(x: np.ndarray) -> np.ndarray:
    """Component-major (6, M, ...) -> (..., M, 6)."""
    return np.moveaxis(x, (0, 1), (-1, -2))


def _eci_to_lvlh(chief_rv: np.ndarray, rel_eci: np.ndarray, chief_acc) -> np.ndarray:
    """Relative ECI states (..., M, 6) -> LVLH (no validation)."""
    acc = None if chief_acc is None else np.moveaxis(chief_acc, -1, 0)
    return _from_soa(eci_rel_to_lvlh_soa(np.moveaxis(chief_rv, -1, 0), _to_soa(rel_eci), acc))


def _lvlh_to_eci_rel(chief_rv: np.ndarray, x_lvlh: np.ndarray, chief_acc) -> np.ndarray:
    """LVLH relative states (..., M, 6) -> relative ECI states (no validation)."""
    acc = None if chief_acc is None else np.moveaxis(chief_acc, -1, 0)
    return _from_soa(lvlh_to_eci_rel_soa(np.moveaxis(chief_rv, -1, 0), _to_soa(x_lvlh), acc))
