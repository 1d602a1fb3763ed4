"""Relative-motion propagation: linear CW, or exact ECI propagation converted to LVLH.

The truth models (``"nonlinear"``, ``"j2"``, ``"j2_drag"``) integrate the chief's absolute
ECI state together with the deputies' ECI states *relative to the chief* (so no precision is
lost to large absolute positions), with RK4, and convert to the chief's LVLH frame at the
step boundaries. The deputies' control accelerations are given in LVLH and held constant in that
rotating frame over a step (zero-order hold), matching the discrete CW model.

Two implementations give the same numbers to rounding: the numpy reference on component-major
arrays (:mod:`._soa`) and the compiled kernel (:mod:`._truth_kernel`, numba), which
:class:`RelativeModel` uses by default for RK4 (``method``); :meth:`RelativeModel.propagate`
runs many steps in one kernel call, converting frames once. ``integrator="dop853"`` integrates
with fixed steps of DOP853's eighth-order solution instead (numpy: :func:`.integrators.dop853_step`);
compiled (:mod:`._span_kernel`), one step spans several input steps (:attr:`RelativeModel.group`:
the 20 physics steps of a 5 s cluster decision in 13 evaluations per body instead of RK4's 80),
their input staircase integrated exactly and the positions inside interpolated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from satenv.errors import SatenvError, SatenvTypeError

from . import _dop853
from ._checks import (
    MAX_STEPS,
    MAX_SUBSTEPS,
    MAX_WORK,
    all_finite,
    as_array,
    first_nonfinite,
    integer,
    positive,
)
from ._soa import derivative_soa, eci_rel_to_lvlh_soa, lvlh_to_eci_rel_soa
from .constants import R_EARTH
from .cw import cw_matrices
from .forces import FORCE_MODELS, ForceModel, acceleration_soa
from .integrators import INTEGRATORS
from .orbit import Orbit, _lvlh_to_eci_rel

MODELS: tuple[str, ...] = ("cw", "nonlinear", "j2", "j2_drag")
"""Names accepted by :func:`simulate` and :class:`RelativeModel`."""

METHODS: tuple[str, ...] = ("auto", "kernel", "numpy")
"""Implementations of the truth models' step (:class:`RelativeModel` ``method``)."""

MAX_SUBSTEP: float = 5.0
"""Default largest internal step of the truth models [s] (RK4 and DOP853)."""

KERNEL_INTEGRATORS: tuple[str, ...] = ("rk4", "dop853")
"""Integrators of the compiled truth kernels (``"euler"`` runs on the numpy path only)."""


def check_model(model: str) -> str:
    """Return ``model`` if it is a known dynamics model name, else raise ``ValueError``."""
    if not isinstance(model, str) or model not in MODELS:
        raise SatenvError(f"unknown dynamics model {model!r}; expected one of {list(MODELS)}")
    return model


def _plane_rotation(orbit: Orbit, angle: float) -> np.ndarray:
    """Rotation by ``angle`` about the orbit normal (the CW chief's circular motion)."""
    rv = orbit.rv
    k = np.cross(rv[:3], rv[3:])
    k /= np.linalg.norm(k)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


@dataclass(frozen=True)
class RelativeModel:
    """A discrete-time relative-dynamics model: ``(x, chief) -> (x_next, chief_next)``.

    Args:
        model: ``"cw"``, ``"nonlinear"``, ``"j2"`` or ``"j2_drag"``.
        orbit: the chief's orbit at epoch (its mean motion is the CW ``n``).
        dt: step length [s].
        substeps: internal RK4 steps per ``dt`` for the truth models (default: steps of at
            most :data:`MAX_SUBSTEP` seconds).
        force: override the force model of a truth model (e.g. ballistic coefficients).
        integrator: ``"rk4"`` (default), ``"dop853"`` (fixed-step eighth order; compiled, one step
            per :attr:`group` input steps in :meth:`propagate`) or ``"euler"`` (tests only; numpy).
        method: the truth models' implementation: ``"numpy"`` (the reference), ``"kernel"`` (the
            compiled kernel; needs numba, RK4 or DOP853) or ``"auto"`` (the kernel when it applies).

    States are LVLH ``(..., M, 6)``, inputs LVLH accelerations ``(..., M, 3)``; the chief is its
    ECI state ``(..., 6)``; under ``"cw"`` it only rotates on the circle of radius ``a`` at the
    mean motion (the CW assumption), which is what the LVLH frame of the CW model follows.
    """

    model: str
    orbit: Orbit
    dt: float
    substeps: int | None = None
    force: ForceModel | None = None
    integrator: str = "rk4"
    method: str = "auto"
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        check_model(self.model)
        if not isinstance(self.orbit, Orbit):
            raise SatenvTypeError(f"orbit must be a satenv.dynamics.Orbit, got {type(self.orbit).__name__}")
        if self.force is not None and not isinstance(self.force, ForceModel):
            raise SatenvTypeError(f"force must be a satenv.dynamics.ForceModel or None, "
                                  f"got {type(self.force).__name__}")
        object.__setattr__(self, "dt", positive(self.dt, "dt (s)"))
        if not isinstance(self.integrator, str) or self.integrator not in INTEGRATORS:
            raise SatenvError(f"unknown integrator {self.integrator!r}; expected one of {sorted(INTEGRATORS)}")
        if self.substeps is None:
            sub = max(1, math.ceil(self.dt / MAX_SUBSTEP - 1e-9))
            if sub > MAX_SUBSTEPS:
                raise SatenvError(
                    f"dt = {self.dt!r} s needs {sub} internal steps of <= {MAX_SUBSTEP} s, above the "
                    f"cap MAX_SUBSTEPS = {MAX_SUBSTEPS} per step (one step would take too long); "
                    "use a smaller dt, or pass substeps <= MAX_SUBSTEPS (coarser integration)")
        else:
            sub = integer(self.substeps, "substeps", maximum=MAX_SUBSTEPS, allow_float=True,
                          why="the cap on internal steps per step, MAX_SUBSTEPS")
        object.__setattr__(self, "substeps", sub)
        if self.force is None and self.model != "cw":
            object.__setattr__(self, "force", FORCE_MODELS[self.model])
        if self.model == "cw":
            a, b = self._cache["ab"] = cw_matrices(self.orbit.n, self.dt)
            self._cache["abT"] = (np.ascontiguousarray(a.T), np.ascontiguousarray(b.T))
            rot = _plane_rotation(self.orbit, self.orbit.n * self.dt)
            # position and velocity rotate alike: one (6, 6) block-diagonal product per step
            self._cache["chief_rotT"] = np.kron(np.eye(2), rot).T.copy()
        self._cache["f"] = derivative_soa(self.force) if self.force else None
        self._cache["kernel"] = self._kernel()

    def _kernel(self):
        """The compiled truth kernel and its force constants, or ``None`` (``method``)."""
        if not isinstance(self.method, str) or self.method not in METHODS:
            raise SatenvError(f"unknown method {self.method!r}; expected one of {list(METHODS)}")
        compiled = self.integrator in KERNEL_INTEGRATORS
        if self.model == "cw" or self.method == "numpy" or (self.method == "auto" and not compiled):
            return None
        if not compiled:
            raise SatenvError(f"method='kernel' integrates with {' or '.join(KERNEL_INTEGRATORS)} only, "
                              f"got integrator={self.integrator!r}")
        try:
            from . import _truth_kernel
            if self.integrator == "dop853":
                from . import _span_kernel
        except ImportError:
            if self.method == "kernel":
                raise SatenvError("method='kernel' needs numba (pip install numba)") from None
            return None
        run = _span_kernel.propagate if self.integrator == "dop853" else _truth_kernel.propagate
        return run, _truth_kernel.force_params(self.force)

    @property
    def group(self) -> int:
        """Input steps per DOP853 step in :meth:`propagate` (``integrator="dop853"``, compiled):
        as many whole steps of ``dt`` as fit in :data:`MAX_SUBSTEP` (1 when ``substeps > 1``)."""
        if self.substeps > 1:
            return 1
        return max(1, math.floor(MAX_SUBSTEP / self.dt + 1e-9))

    @property
    def ab(self) -> tuple[np.ndarray, np.ndarray]:
        """The discrete CW ``(A, B)`` for this ``dt`` (any model: they are the linear model)."""
        if "ab" not in self._cache:
            self._cache["ab"] = cw_matrices(self.orbit.n, self.dt)
        return self._cache["ab"]

    def linear_step_matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """``(A^T, B^T, R^T)`` of the ``cw`` model's step (states, inputs, chief; contiguous), or
        ``None`` for the nonlinear models: for compiled steppers that fuse :meth:`step`."""
        if self.model != "cw":
            return None
        return (*self._cache["abT"], self._cache["chief_rotT"])

    def initial_chief(self) -> np.ndarray:
        """The chief's ECI state at epoch (6,)."""
        return self.orbit.rv

    def step(self, x: np.ndarray, u: np.ndarray | None, chief: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Advance LVLH states ``x`` (..., M, 6) by one ``dt`` under LVLH accelerations ``u``.

        No input validation here (this is the hot path): use :func:`simulate` or validate at
        the boundary.
        """
        if u is None:
            u = np.zeros((*x.shape[:-1], 3))
        if self._cache["kernel"] is not None:
            return self.propagate(x, u[None], chief)[:2]
        if self.model == "cw":
            a_t, b_t = self._cache["abT"]
            chief_next = np.asarray(chief, dtype=float) @ self._cache["chief_rotT"]
            # row matmuls on the flattened states: one BLAS call each instead of a Python-level
            # loop over the stacked (M, 6) @ (6, 6) products that a batched ``@`` performs.
            if u.shape[:-1] != x.shape[:-1]:          # broadcasting inputs: the general form
                return x @ a_t + u @ b_t, chief_next
            out = x.reshape(-1, 6) @ a_t
            out += u.reshape(-1, 3) @ b_t
            return out.reshape(x.shape), chief_next
        f = self._cache["f"]
        force = self.force
        stepper = INTEGRATORS[self.integrator]
        lead, m = x.shape[:-2], x.shape[-2]
        n = int(np.prod(lead)) if lead else 1
        xs = np.ascontiguousarray(x.reshape(n, m, 6).transpose(2, 1, 0))        # (6, M, B)
        cs = np.ascontiguousarray(np.broadcast_to(chief, (*lead, 6)).reshape(n, 6).T)  # (6, B)
        us = np.ascontiguousarray(np.broadcast_to(u, (*lead, m, 3)).reshape(n, m, 3).transpose(2, 1, 0))
        y = np.empty((6, 1 + m, n))
        y[:, 0] = cs
        y[:, 1:] = lvlh_to_eci_rel_soa(cs, xs, acceleration_soa(cs[:3], cs[3:], force, force.ballistic_chief))
        h = self.dt / self.substeps
        rhs = lambda t, yy: f(t, yy, us)  # noqa: E731
        for k in range(self.substeps):
            y = stepper(rhs, k * h, y, h)
        c_next = y[:, 0]
        acc_c = acceleration_soa(c_next[:3], c_next[3:], force, force.ballistic_chief)
        x_next = eci_rel_to_lvlh_soa(c_next, y[:, 1:], acc_c)
        return (np.ascontiguousarray(x_next.transpose(2, 1, 0)).reshape(x.shape),
                np.ascontiguousarray(c_next.T).reshape((*lead, 6)))


    def propagate(self, x: np.ndarray, u: np.ndarray, chief: np.ndarray, positions: bool = False,
                  common: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``len(u)`` steps at once: LVLH states ``x`` (..., M, 6) under the inputs ``u`` (S, ..., M, 3)
        (``u[s]`` held over step ``s``; a broadcast view is not copied), plus ``common`` (S, ..., 3),
        an input the same for every deputy (e.g. a disturbance), when given; returns ``(x_next,
        chief_next, path)``, ``path`` the LVLH positions after every step (S, ..., M, 3) when
        ``positions`` (else ``None``).

        With ``integrator="rk4"`` the same as ``S`` calls of :meth:`step` (the compiled kernel does
        it in one call with the frame conversions at the ends only). With ``"dop853"`` the compiled
        kernel takes one DOP853 step per :attr:`group` steps, the inputs' staircase inside it
        integrated exactly and the positions inside it interpolated (:mod:`._span_kernel`); the
        numpy path takes DOP853 steps of ``dt / substeps``. No input validation (the hot path).
        """
        kernel = self._cache["kernel"]
        u, chief = np.asarray(u), np.asarray(chief)
        n_steps = u.shape[0]
        span = kernel is not None and self.integrator == "dop853"
        if common is not None and not span:
            u = u + np.asarray(common)[..., None, :]
        if kernel is None:
            path = np.empty((n_steps, *x.shape[:-1], 3)) if positions else None
            for s in range(n_steps):
                x, chief = self.step(x, u[s], chief)
                if positions:
                    path[s] = x[..., :3]
            return x, chief, path
        run, params = kernel
        lead, m = x.shape[:-2], x.shape[-2]
        n = math.prod(lead)
        xs = np.ascontiguousarray(x.reshape(n, m, 6), dtype=float)
        if chief.shape != (*lead, 6):
            chief = np.broadcast_to(chief, (*lead, 6))
        cs = np.ascontiguousarray(chief.reshape(n, 6), dtype=float)
        if u.shape != (n_steps, *lead, m, 3):
            u = np.broadcast_to(u, (n_steps, *lead, m, 3))
        held = span and n_steps > 0 and u.strides[0] == 0          # one row held over every step
        us = np.ascontiguousarray(u[:1] if held else u, dtype=float).reshape(-1, n, m, 3)
        x_next, chief_next = np.empty_like(xs), np.empty_like(cs)
        path = np.empty((n_steps if positions else 0, n, m, 3))
        if span:
            if common is None:
                cm = np.zeros((0, n, 3))
            else:
                common = np.asarray(common, dtype=float)
                if common.shape != (n_steps, *lead, 3):
                    common = np.broadcast_to(common, (n_steps, *lead, 3))
                cm = np.ascontiguousarray(common).reshape(n_steps, n, 3)
            run(xs, cs, us, cm, n_steps, self.group, self.substeps, self.dt, params, _dop853.A, _dop853.B,
                _dop853.C, x_next, chief_next, path)
        else:
            run(xs, cs, us, self.substeps, self.dt / self.substeps, params, x_next, chief_next, path)
        return (x_next.reshape(x.shape), chief_next.reshape((*lead, 6)),
                path.reshape((n_steps, *lead, m, 3)) if positions else None)


def simulate(model: str, x0, *, orbit: Orbit, dt: float, steps: int, u=None,
             substeps: int | None = None, force: ForceModel | None = None) -> np.ndarray:
    """Propagate LVLH relative states and return the trajectory ``(steps + 1, M, 6)``.

    Args:
        model: ``"cw"``, ``"nonlinear"``, ``"j2"`` or ``"j2_drag"``.
        x0: initial LVLH relative states (M, 6) [m, m/s] of M deputies.
        orbit: the chief's :class:`Orbit` at epoch.
        dt: output (and input hold) step [s].
        steps: number of steps.
        u: optional LVLH control accelerations (steps, M, 3) [m/s^2], held per step.
        substeps: internal RK4 steps per ``dt`` (truth models; default steps <= 5 s).
        force: optional :class:`ForceModel` override for the truth models.

    Example:
        >>> from satenv.dynamics import Orbit, simulate
        >>> xs = simulate("j2", [[0.0, 1000.0, 0.0, 0.0, 0.0, 0.0]],
        ...               orbit=Orbit(a=6878e3, i=0.9), dt=10.0, steps=3)
        >>> xs.shape
        (4, 1, 6)
    """
    check_model(model)
    x0 = as_array(x0, "x0", (6,))
    if x0.ndim != 2:
        raise SatenvError(f"x0 must have shape (M, 6), got {x0.shape}; for one deputy use x0[None]")
    steps = integer(steps, "steps", minimum=0, maximum=MAX_STEPS, allow_float=True,
                    why="the cap on step counts, MAX_STEPS")
    if u is not None:
        u = as_array(u, "u", (3,))
        if u.shape != (steps, x0.shape[0], 3):
            raise SatenvError(f"u must have shape (steps, M, 3) = {(steps, x0.shape[0], 3)}, "
                              f"got {u.shape}")
    prop = RelativeModel(model, orbit, dt, substeps=substeps, force=force)
    if model != "cw":
        if steps * prop.substeps > MAX_WORK:
            raise SatenvError(
                f"steps * substeps = {steps} * {prop.substeps} internal steps exceeds the cap "
                f"MAX_WORK = {MAX_WORK} of one simulate call (it would run for minutes); "
                "split the propagation into several calls or use a larger dt")
        _check_outside_earth(prop, x0)
    out = np.empty((steps + 1, *x0.shape))
    out[0] = x0
    chief = prop.initial_chief()
    with np.errstate(all="ignore"):  # non-finite results are reported below, with where
        for k in range(steps):
            out[k + 1], chief = prop.step(out[k], None if u is None else u[k], chief)
    if not all_finite(out):
        k = int(np.flatnonzero(~np.isfinite(out).reshape(steps + 1, -1).all(axis=1))[0])
        labels = [f"deputy {i}" for i in range(x0.shape[0])]
        raise SatenvError(f"simulate({model!r}): non-finite {first_nonfinite({'state': out[k]}, labels)} "
                          f"at step {k}; the inputs "
                          "(x0, u, orbit, dt) drive the propagation out of the float range")
    return out


def _check_outside_earth(prop: RelativeModel, x0: np.ndarray) -> None:
    """Truth models: every deputy must start above the Earth's surface (the gravity model is
    singular at its centre)."""
    chief = prop.initial_chief()
    rel = _lvlh_to_eci_rel(chief, x0, None)
    radius = np.sqrt(((chief[:3] + rel[:, :3]) ** 2).sum(axis=1))
    inside = np.flatnonzero(~(radius > R_EARTH))
    if inside.size:
        i = int(inside[0])
        raise SatenvError(f"x0 row {i} puts deputy {i} at {radius[i]:.6g} m from the Earth's "
                          f"centre, inside the Earth (R = {R_EARTH:.0f} m); x0 is relative to the "
                          "chief in LVLH [m, m/s]")
