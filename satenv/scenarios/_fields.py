"""Validation of scenario fields (shared by every scenario dataclass's ``__post_init__``).

Each function returns the cleaned value or raises :class:`satenv.errors.SatenvError` (a
``ValueError``; :class:`satenv.errors.SatenvTypeError` for a value of the wrong kind) naming the
field, what was received and what is expected. The number/array rules and the work caps are
those of :mod:`satenv.dynamics._checks`.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from satenv.dynamics._checks import (
    MAX_STEPS,
    MAX_SUBSTEPS,
    derived,
    numeric,
    positive,
    show,
)
from satenv.dynamics._checks import integer as _integer
from satenv.dynamics._checks import real as _real
from satenv.errors import SatenvError, SatenvTypeError

__all__ = ["MAX_AGENTS", "MAX_INT", "MAX_MAGNITUDE", "MAX_RELATIVE_SPEED", "MAX_STEPS", "MAX_SUBSTEPS", "SatenvError",
           "array", "at_most", "derived", "flag", "from_preset", "integer", "nested", "number", "real",
           "obs_neighbours", "orbit_step", "spreads_in_region", "states_in_region", "steps", "vector"]

MAX_AGENTS: int = 1024
"""Cap on the number of agents of a scenario: the swarm sizes the envs are built and measured for
(per-agent cost flat in N, ``satenv.bench.perf --sections scaling``); the dense per-scenario
matrices (graph adjacency, Laplacian, allocation cost) stay below 10 MB at this size."""

MAX_RELATIVE_SPEED: float = 2 * 11.2e3
"""Largest relative speed [m/s] of an initial state: two bound Earth orbits never move faster
than twice the escape speed at the surface (11.2 km/s) relative to each other."""


MAX_MAGNITUDE: float = 1e30
"""Cap on the magnitude of every real scenario field (SI): far above any physical quantity of a
scenario (mu = 4e14 m^3/s^2), and low enough that products of a few such stay far from the
float64 range (1.8e308), so a field whose derived quantities would overflow is rejected by its
own name (e.g. ``desired_error=[0, -8e300, ...]``), not by the env's first-step probe."""

MAX_INT: int = 2**31 - 1
"""Cap on every integer scenario field without a tighter one (counts, sizes)."""


def _bounded(arr: np.ndarray, name: str, value: Any) -> None:
    if arr.size and not float(np.abs(arr).max()) <= MAX_MAGNITUDE:
        raise SatenvError(f"{name} must have magnitude <= MAX_MAGNITUDE = {MAX_MAGNITUDE:g} (physically "
                          f"sized SI values), got {show(value)}")


def integer(value: Any, name: str, *, minimum: int = 1, maximum: int | None = None, why: str = "",
            allow_float: bool = False) -> int:
    """An int in ``[minimum, maximum]`` (``maximum`` defaults to :data:`MAX_INT`); bools rejected."""
    if maximum is None:
        maximum, why = MAX_INT, why or "the cap on scenario integers, satenv.scenarios._fields.MAX_INT"
    return _integer(value, name, minimum=minimum, maximum=maximum, why=why, allow_float=allow_float)


MAX_OBS_NEIGHBOURS: int = 64
"""Cap on the neighbour slots of a fixed observation layout (``obs_neighbours``)."""


def obs_neighbours(value: Any, name: str = "obs_neighbours") -> int | None:
    """``None`` (the env's own observation layout) or the number of neighbour slots ``K`` of the
    fixed, team-size-independent layout, an int in ``[1, MAX_OBS_NEIGHBOURS]``."""
    if value is None:
        return None
    return integer(value, name, minimum=1, maximum=MAX_OBS_NEIGHBOURS, why="MAX_OBS_NEIGHBOURS")


def real(value: Any, name: str, expected: str = "a finite real number") -> float:
    """A finite float of magnitude at most :data:`MAX_MAGNITUDE` (bools, complex, text rejected)."""
    v = _real(value, name, expected)
    _bounded(np.asarray(v), name, value)
    return v


def number(value: Any, name: str, *, allow_zero: bool = False) -> float:
    """A finite float ``> 0`` (``>= 0`` with ``allow_zero``) of magnitude at most
    :data:`MAX_MAGNITUDE`; booleans are rejected."""
    v = positive(value, name, allow_zero=allow_zero)
    _bounded(np.asarray(v), name, value)
    return v


def flag(value: Any, name: str) -> bool:
    """A bool (``True``/``False``, or a numpy bool)."""
    if not isinstance(value, bool | np.bool_):
        raise SatenvError(f"{name} must be True or False, got {show(value)}")
    return bool(value)


def steps(value: Any, name: str) -> int:
    """An episode length: an int in ``[1, MAX_STEPS]``."""
    return integer(value, name, maximum=MAX_STEPS,
                   why="the cap on step counts, satenv.dynamics._checks.MAX_STEPS")


def array(value: Any, name: str, shape: tuple[int, ...] | None = None, ndim: int | None = None) -> np.ndarray:
    """A finite float array (entries of magnitude at most :data:`MAX_MAGNITUDE`), optionally of
    an exact ``shape`` or number of dimensions."""
    arr = numeric(value, name)
    _bounded(arr, name, value)
    if shape is not None and arr.shape != shape:
        raise SatenvError(f"{name} must have shape {shape}, got {arr.shape}: {show(value)}")
    if ndim is not None and arr.ndim != ndim:
        raise SatenvError(f"{name} must be a {ndim}-d array, got shape {arr.shape}")
    return arr


def vector(value: Any, name: str, length: int | None = None) -> tuple[float, ...]:
    """A flat tuple of finite floats of magnitude at most :data:`MAX_MAGNITUDE` (of ``length``
    entries when given)."""
    arr = numeric(value, name).ravel()
    _bounded(arr, name, value)
    if length is not None and arr.shape != (length,):
        raise SatenvError(f"{name} must have {length} entries, got {arr.size}: {show(value)}")
    return tuple(float(v) for v in arr)


def states_in_region(x: Any, name: str, max_distance: float, *, n_agents: int | None = None,
                     width: int = 6) -> np.ndarray:
    """Initial states ``(M, width)`` (columns 0-2 position, 3-5 velocity) inside the scenario's
    allowed region: ``|p| <= max_distance`` and ``|v| <= MAX_RELATIVE_SPEED``; at most
    ``MAX_AGENTS`` rows (exactly ``n_agents`` when given)."""
    arr = numeric(x, name)
    rows = "M" if n_agents is None else n_agents
    if arr.ndim != 2 or arr.shape[1] != width or not 1 <= arr.shape[0] <= MAX_AGENTS or (
            n_agents is not None and arr.shape[0] != n_agents):
        raise SatenvError(f"{name} must have shape ({rows}, {width}) with 1 <= M <= {MAX_AGENTS} "
                          f"(one row per agent), got shape {arr.shape}")
    dist = np.sqrt((arr[:, :3] ** 2).sum(axis=1))
    speed = np.sqrt((arr[:, 3:6] ** 2).sum(axis=1))
    for what, values, bound in (("position", dist, max_distance), ("speed", speed, MAX_RELATIVE_SPEED)):
        far = np.flatnonzero(~(values <= bound))
        if far.size:
            i = int(far[0])
            raise SatenvError(f"{name}: row {i} has {what} norm {values[i]:.6g}, outside the allowed "
                              f"region (<= {bound:.6g}; max_distance for positions [m], "
                              f"MAX_RELATIVE_SPEED for velocities [m/s])")
    return arr


def at_most(value: float, name: str, bound: float, bound_name: str) -> float:
    """``value`` if it is ``<= bound`` (``bound_name`` says which limit), else a clear error."""
    if not value <= bound:
        raise SatenvError(f"{name} = {value!r} must be <= {bound_name} = {bound!r}")
    return value


def spreads_in_region(position_spread: float, velocity_spread: float, max_distance: float,
                      position_name: str = "random_position_spread",
                      velocity_name: str = "random_velocity_spread") -> None:
    """Random initial states stay in the allowed region: spreads at most ``max_distance`` [m]
    and ``MAX_RELATIVE_SPEED`` [m/s]."""
    at_most(position_spread, position_name, max_distance, "max_distance")
    at_most(velocity_spread, velocity_name, MAX_RELATIVE_SPEED, "MAX_RELATIVE_SPEED [m/s]")


def orbit_step(mean_motion: float, dt: float, inputs: str) -> None:
    """One decision step is shorter than an orbital period (``n dt <= 2 pi``) and the orbit
    radius implied by ``inputs`` is above the Earth's surface."""
    if not mean_motion * dt <= 2 * np.pi:
        raise SatenvError(f"dt = {dt!r} s is longer than the orbital period 2 pi / n = "
                          f"{2 * np.pi / mean_motion:.6g} s of {inputs}; a decision step must be "
                          "shorter than one orbit")


def nested(arr: np.ndarray):
    """An array as nested tuples of floats (hashable, for frozen dataclasses)."""
    return tuple(nested(a) for a in arr) if arr.ndim > 1 else tuple(float(v) for v in arr)


def from_preset(presets: dict[str, Any], preset: str, kind: str, overrides: dict[str, Any]) -> Any:
    """``presets[preset]`` with ``overrides`` applied through its ``with_overrides`` (validated)."""
    if not isinstance(preset, str) or preset not in presets:
        raise SatenvError(f"unknown {kind} preset {show(preset)}; expected one of {sorted(presets)}")
    base = presets[preset]
    for f in dataclasses.fields(base):  # text fields take text (a numpy array would compare elementwise)
        if f.name in overrides and f.type in ("str", str) and not isinstance(overrides[f.name], str):
            raise SatenvTypeError(f"{f.name} must be a string, got {type(overrides[f.name]).__name__}: "
                                  f"{show(overrides[f.name])}")
    return base.with_overrides(**overrides) if overrides else base
