"""Accelerations acting on a spacecraft in ECI: two-body gravity, J2, atmospheric drag.

The public functions are batched over leading axes: positions/velocities ``(..., 3)``;
:func:`acceleration_soa` is the fused kernel on component-major arrays ``(3, ...)`` that
:func:`acceleration` and the truth-model step (:mod:`._soa`, :mod:`.propagate`) evaluate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .constants import J2_EARTH, MU_EARTH, OMEGA_EARTH, R_EARTH


@dataclass(frozen=True)
class ForceModel:
    """Which perturbations act, and their parameters (SI).

    Args:
        j2: include Earth's J2 zonal harmonic.
        drag: include atmospheric drag (exponential atmosphere co-rotating with the Earth).
        mu, r_earth, j2_coef, omega_earth: Earth constants.
        rho0, h0, scale_height: exponential density ``rho0 exp(-(h - h0) / H)`` [kg/m^3, m, m];
            the defaults are Vallado's 500 km band (Table 8-4).
        ballistic_chief, ballistic_deputy: ``C_d A / m`` [m^2/kg] of chief and deputies; a
            difference between the two gives differential drag.
    """

    j2: bool = False
    drag: bool = False
    mu: float = MU_EARTH
    r_earth: float = R_EARTH
    j2_coef: float = J2_EARTH
    omega_earth: float = OMEGA_EARTH
    rho0: float = 6.967e-13
    h0: float = 500e3
    scale_height: float = 63.822e3
    ballistic_chief: float = 0.01
    ballistic_deputy: float = 0.01

    def __post_init__(self) -> None:
        for name in ("mu", "r_earth", "rho0", "scale_height"):
            v = getattr(self, name)
            if not np.isfinite(v) or v <= 0:
                raise ValueError(f"ForceModel.{name} must be finite and > 0, got {v!r}")
        for name in ("j2_coef", "omega_earth", "h0", "ballistic_chief", "ballistic_deputy"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise ValueError(f"ForceModel.{name} must be finite and >= 0, got {v!r}")


FORCE_MODELS: dict[str, ForceModel] = {
    "nonlinear": ForceModel(),
    "j2": ForceModel(j2=True),
    "j2_drag": ForceModel(j2=True, drag=True),
}
"""The named truth force models of :func:`satenv.dynamics.simulate` (``"cw"`` is linear)."""


def two_body(r: np.ndarray, mu: float = MU_EARTH) -> np.ndarray:
    """Point-mass gravity ``-mu r / |r|^3``."""
    rn2 = np.einsum("...i,...i->...", r, r)
    return -mu * r / (rn2 * np.sqrt(rn2))[..., None]


def j2(r: np.ndarray, mu: float = MU_EARTH, r_earth: float = R_EARTH,
       j2_coef: float = J2_EARTH) -> np.ndarray:
    """J2 perturbing acceleration (the ECI z axis is Earth's rotation axis)."""
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    rn2 = x * x + y * y + z * z
    k = -1.5 * j2_coef * mu * r_earth**2 / (rn2 * rn2 * np.sqrt(rn2))
    z2 = 5.0 * z * z / rn2
    return np.stack([k * x * (1.0 - z2), k * y * (1.0 - z2), k * z * (3.0 - z2)], axis=-1)


def drag(r: np.ndarray, v: np.ndarray, ballistic: float | np.ndarray, model: ForceModel) -> np.ndarray:
    """Drag ``-1/2 rho (C_d A / m) |v_rel| v_rel`` with ``v_rel = v - omega_E x r``."""
    omega = np.array([0.0, 0.0, model.omega_earth])
    v_rel = v - np.cross(omega, r)
    h = np.linalg.norm(r, axis=-1) - model.r_earth
    rho = model.rho0 * np.exp(-(h - model.h0) / model.scale_height)
    speed = np.linalg.norm(v_rel, axis=-1)
    return -0.5 * (rho * np.asarray(ballistic) * speed)[..., None] * v_rel


def acceleration_soa(r: np.ndarray, v: np.ndarray, model: ForceModel, ballistic: float) -> np.ndarray:
    """Two-body (+ J2) (+ drag) acceleration for component-major ``r, v`` of shape ``(3, ...)``."""
    x, y, z = r[0], r[1], r[2]
    rn2 = x * x + y * y + z * z
    inv_r3 = 1.0 / (rn2 * np.sqrt(rn2))
    out = np.empty_like(r)
    if model.j2:
        k = -1.5 * model.j2_coef * model.r_earth**2 / rn2
        z2 = 5.0 * z * z / rn2
        kxy = -model.mu * inv_r3 * (1.0 + k * (z2 - 1.0))
        kz = -model.mu * inv_r3 * (1.0 + k * (z2 - 3.0))
        out[0] = kxy * x
        out[1] = kxy * y
        out[2] = kz * z
    else:
        kk = -model.mu * inv_r3
        out[0] = kk * x
        out[1] = kk * y
        out[2] = kk * z
    if model.drag:
        w = model.omega_earth
        vr0, vr1, vr2 = v[0] + w * y, v[1] - w * x, v[2]       # v - omega_E x r
        h = np.sqrt(rn2) - model.r_earth
        rho = model.rho0 * np.exp(-(h - model.h0) / model.scale_height)
        kd = -0.5 * (rho * ballistic * np.sqrt(vr0 * vr0 + vr1 * vr1 + vr2 * vr2))
        out[0] += kd * vr0
        out[1] += kd * vr1
        out[2] += kd * vr2
    return out


def acceleration(r: np.ndarray, v: np.ndarray, model: ForceModel, ballistic: float) -> np.ndarray:
    """Total natural (uncontrolled) acceleration of a spacecraft under ``model`` (``(..., 3)``)."""
    v_c = None if v is None else np.moveaxis(v, -1, 0)
    return np.moveaxis(acceleration_soa(np.moveaxis(r, -1, 0), v_c, model, ballistic), 0, -1)
