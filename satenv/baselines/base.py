"""What every baseline shares: the policy interface, errors, config validation, the solver guard.

A policy has ``reset(seed=None)`` and ``act(observations) -> actions`` (dicts keyed by agent,
actions normalised to ``[-1, 1]^d``), and an ``info`` dict with at least ``"fallbacks"`` (solver
failures replaced by a safe action, counted since ``reset``) and ``"solver_status"`` (the status
of the last solve: ``"solved"``-like on success, else why it failed).

A scripted baseline class declares ``name``, ``env_ids`` (the satenv env ids it can control)
and a classmethod ``supports(env)``; it is built as ``Baseline(env, config=None, **options)``
with one frozen config dataclass (:func:`config_from_options`). :func:`check_env` gives the one
error for a non-env (:class:`BaselineTypeError`) or an env the baseline cannot control
(:class:`BaselineError`). Every solver call goes through :func:`guarded_solve`, which also
enforces the baseline's per-solve time limit (each config's ``solve_time_limit`` [s],
validated by :func:`time_limit`).
"""

from __future__ import annotations

import math
import numbers
import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import fields
from typing import Any, Protocol, TypeVar, runtime_checkable

import numpy as np

from satenv.dynamics._checks import show

__all__ = [
    "Baseline", "BaselineError", "BaselineTypeError", "Policy", "RandomPolicy", "ZeroPolicy", "check_env",
    "config_from_options", "flag", "choice", "guard_nonfinite", "guarded_solve", "is_satenv_env", "new_info",
    "nlpsol_cached", "number", "integer", "record_fallback", "row_violation", "weights",
]

C = TypeVar("C")

MAX_HORIZON = 200
"""Cap on every prediction horizon (steps) of a baseline config: bounded work per decision (the
papers use 30-50; at 200 a DMPC QP builds in ~2 s and an NMPC / tube-RDMPC NLP takes 10-15 s for
its first solve, at 1000 they took minutes and GBs)."""
MAX_SOLVE_TIME = 3600.0
"""Largest accepted per-solve time limit [s] (``solve_time_limit`` of every baseline config)."""
MAX_ITERATIONS = 100_000
"""Cap on every iteration count (solver iterations, Jacobi / convex-step / GMRES iterations)."""


class BaselineError(ValueError):
    """Bad baseline input: an unknown or invalid option, or an env the baseline cannot control."""


class BaselineTypeError(TypeError):
    """A baseline was given something that is not a satenv env."""


# ---------------------------------------------------------------------------------------------
# env checks
# ---------------------------------------------------------------------------------------------
def _env_ids() -> tuple[str, ...]:
    import satenv

    return tuple(satenv.ENV_IDS)


def is_satenv_env(env: Any) -> bool:
    """True for a satenv PettingZoo env (``metadata["name"]`` is a satenv env id, a scenario)."""
    meta = getattr(type(env), "metadata", None)
    return (isinstance(meta, dict) and meta.get("name") in _env_ids()
            and getattr(env, "scenario", None) is not None)


def env_name(env: Any) -> str:
    """The satenv env id of ``env`` (``env.metadata["name"]``)."""
    return type(env).metadata["name"]


def check_env(cls: type, env: Any) -> None:
    """Raise unless ``cls`` (a baseline class with ``supports``/``env_ids``) can control ``env``."""
    if not is_satenv_env(env):
        raise BaselineTypeError(
            f"{cls.__name__} needs a satenv env (e.g. satenv.make({cls.env_ids[0]!r})), got "
            f"{type(env).__name__} {env!r:.80}")
    if not cls.supports(env):
        raise BaselineError(
            f"{cls.__name__} cannot control {env_name(env)} (scenario "
            f"{getattr(env.scenario, 'name', '?')!r}); it supports: {cls.supported()}")


class Baseline:
    """Base of the solver-based baselines: what envs a class supports, and the env check.

    Subclasses set ``name``, ``env_ids``, ``cheap`` (False for a per-decision NLP, skipped by
    quick evaluations) and may refine :meth:`supports` by scenario properties.
    """

    name: str = ""
    env_ids: tuple[str, ...] = ()
    cheap: bool = True

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        act = cls.__dict__.get("act")
        if act is not None and not getattr(act, "guards_nonfinite", False):
            cls.act = guard_nonfinite(act)

    @classmethod
    def supports(cls, env: Any) -> bool:
        """True when this baseline can control ``env`` (by env id and scenario)."""
        return is_satenv_env(env) and env_name(env) in cls.env_ids

    @classmethod
    def supported(cls) -> str:
        """What :meth:`supports` accepts, for error messages."""
        return f"satenv envs {list(cls.env_ids)}"


NONFINITE_STATE = "non-finite env state: zero action (the solver is not run)"
"""``info["solver_status"]`` of a decision skipped because ``env.state()`` held NaN/inf."""
NONFINITE_ACTION = "non-finite action: zero action"
"""``info["solver_status"]`` of an agent whose computed action held NaN/inf."""


def guard_nonfinite(act: Callable[..., dict[str, np.ndarray]]) -> Callable[..., dict[str, np.ndarray]]:
    """``act`` of a :class:`Baseline` behind the non-finite guard (applied to every subclass's
    ``act``): when the env's true state (``self.env.state()``) holds NaN/inf the solver is not run
    and every agent gets the zero action (no thrust); an agent whose computed action holds NaN/inf
    gets the zero action too. Each such agent counts one ``info["fallbacks"]`` and
    ``info["solver_status"]`` says why: the flagged safe action, never a NaN thrust."""
    from functools import wraps

    @wraps(act)
    def guarded(self: Any, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        env = getattr(self, "env", None)
        state = env.state() if env is not None and callable(getattr(env, "state", None)) else None
        if state is not None and not np.isfinite(np.asarray(state, dtype=float)).all():
            for _ in observations:
                record_fallback(self.info, NONFINITE_STATE)
            return {a: np.zeros(env.action_space(a).shape, np.float32) for a in observations}
        actions = act(self, observations)
        for a, u in actions.items():
            if not np.isfinite(u).all():
                actions[a] = np.zeros_like(u)
                record_fallback(self.info, NONFINITE_ACTION)
        return actions

    guarded.guards_nonfinite = True   # type: ignore[attr-defined]
    return guarded


# ---------------------------------------------------------------------------------------------
# configs
# ---------------------------------------------------------------------------------------------
def config_from_options(config_cls: type[C], options: dict[str, Any], owner: str,
                        base: C | None = None) -> C:
    """``base`` (default: ``config_cls()``) with ``options`` replaced; unknown keys rejected.

    The one entry point from keyword options to a baseline's frozen config, so every baseline
    gives the same :class:`BaselineError` for an unknown option.
    """
    known = [f.name for f in fields(config_cls) if f.init]
    unknown = sorted(set(options) - set(known))
    if unknown:
        raise BaselineError(f"{owner}: unknown option(s) {unknown}; accepted: {sorted(known)}")
    values = {} if base is None else {k: getattr(base, k) for k in known}
    return config_cls(**{**values, **options})


MAX_OPTION = 1e30
"""Default upper bound of a real option: far above any gain, margin or tolerance, low enough
that squares and products of a few stay inside the float range (``keepout_margin=1e300``
overflowed in the NMPC build)."""


def number(owner: str, name: str, value: Any, *, low: float = 0.0, zero_ok: bool = False,
           high: float = MAX_OPTION) -> float:
    """A finite real ``> low`` (``>= low`` with ``zero_ok``) and ``<= high`` (default
    :data:`MAX_OPTION`); no bools/complex."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
        raise BaselineError(f"{owner} option {name} must be a real number, got {show(value)}")
    try:
        v = float(value)
    except OverflowError:
        raise BaselineError(f"{owner} option {name} must be a finite real number, got {show(value)} "
                            "(too large for a float)") from None
    ok = math.isfinite(v) and (v >= low if zero_ok else v > low) and v <= high
    if not ok:
        rng = f"{'>=' if zero_ok else '>'} {low:g}" + (f" and <= {high:g}" if high < math.inf else "")
        raise BaselineError(f"{owner} option {name} must be finite and {rng}, got {show(value)}")
    return v


def integer(owner: str, name: str, value: Any, *, low: int = 1, high: int = MAX_ITERATIONS) -> int:
    """An int in ``[low, high]`` (the cap keeps the work bounded); no bools/floats."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Integral):
        raise BaselineError(f"{owner} option {name} must be an int, got {show(value)}")
    if not low <= int(value) <= high:
        raise BaselineError(f"{owner} option {name} must be in [{low}, {high}] (bounded work), "
                            f"got {show(value)}")
    return int(value)


def time_limit(owner: str, name: str, value: Any) -> float | None:
    """A per-solve time limit [s]: ``None`` (no limit) or a number in ``(0, MAX_SOLVE_TIME]``."""
    return None if value is None else number(owner, name, value, high=MAX_SOLVE_TIME)


def flag(owner: str, name: str, value: Any) -> bool:
    if not isinstance(value, bool | np.bool_):
        raise BaselineError(f"{owner} option {name} must be True or False, got {show(value)}")
    return bool(value)


def choice(owner: str, name: str, value: Any, choices: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in choices:
        raise BaselineError(f"{owner} option {name} must be one of {choices}, got {show(value)}")
    return value


def weights(owner: str, name: str, value: Any, length: int | None = None, *,
            zero_ok: bool = True) -> tuple[float, ...]:
    """A flat tuple of finite real weights ``>= 0`` (``> 0`` unless ``zero_ok``)."""
    if isinstance(value, str | bytes) or np.iscomplexobj(value) or np.ma.isMaskedArray(value):
        raise BaselineError(f"{owner} option {name} must be a sequence of real numbers, got {show(value)}")
    try:
        seq = list(np.ravel(np.asarray(value, dtype=object)))
    except (TypeError, ValueError):
        raise BaselineError(f"{owner} option {name} must be a sequence of numbers, got {show(value)}") from None
    out = tuple(number(owner, name, v, zero_ok=zero_ok) for v in seq)
    if length is not None and len(out) != length:
        raise BaselineError(f"{owner} option {name} must have {length} entries, got {len(out)}: {show(value)}")
    return out


def validate(cfg: Any, owner: str, rules: dict[str, Callable[[str, str, Any], Any]]) -> None:
    """Apply ``rules[field](owner, field, value)`` to a frozen config and store the cleaned values."""
    for name, rule in rules.items():
        object.__setattr__(cfg, name, rule(owner, name, getattr(cfg, name)))


# ---------------------------------------------------------------------------------------------
# compiled NLP solvers, built once per process
# ---------------------------------------------------------------------------------------------
JIT_OPTIONS: dict[str, Any] = {"jit": True, "compiler": "shell", "jit_temp_suffix": True,
                               "jit_options": {"flags": ["-O1"], "directory": tempfile.gettempdir() + os.sep}}
"""CasADi options that compile the NLP's functions (objective, constraints, their derivatives)
to C with gcc once; the solver's algorithm and its answers are those of the uncompiled build."""
_NLPSOL_CACHE: dict[tuple, Any] = {}


def nlpsol_cached(key: tuple, build: Callable[[], Any]) -> Any:
    """``build()`` (a CasADi ``nlpsol`` and its row data) once per process for ``key``.

    ``key`` must name everything the build depends on (the config fields and scenario numbers
    that enter the problem), so every episode, env and controller with the same problem reuses
    one compiled solver and no episode pays the compile cost again.
    """
    if key not in _NLPSOL_CACHE:
        _NLPSOL_CACHE[key] = build()
    return _NLPSOL_CACHE[key]


# ---------------------------------------------------------------------------------------------
# the solver guard
# ---------------------------------------------------------------------------------------------
def new_info(**extra: Any) -> dict[str, Any]:
    """A fresh policy ``info`` dict (``fallbacks`` 0, ``solver_status`` ``"not run"``)."""
    return {"fallbacks": 0, "solver_status": "not run", **extra}


def record_fallback(info: dict[str, Any], status: str) -> None:
    """Count a fallback to the safe action in ``info`` and record why."""
    info["fallbacks"] = info.get("fallbacks", 0) + 1
    info["solver_status"] = status


def guarded_solve(info: dict[str, Any], solve: Callable[[], tuple[Any, bool, str]], *,
                  shape: tuple[int, ...], lower: Any = None, upper: Any = None,
                  violation: Callable[[np.ndarray], float] | None = None, tol: float = 1e-6,
                  violation_tol: float = 1e-6, fallback: bool = True,
                  time_limit: float | None = None) -> np.ndarray | None:
    """Run one solver call; return its point, or ``None`` when it must not be used.

    ``solve()`` returns ``(x, ok, status)`` with ``ok`` the solver's own success report. The call
    fails on any exception, ``ok`` False, a point of another ``shape``, a non-finite entry, a
    violation of ``lower <= x <= upper`` by more than ``tol`` (scaled by ``max(1, |bound|)``), or
    ``violation(x) > violation_tol`` (a cheap check of the solver's constraints, e.g. ``A x`` rows),
    or a solve that took longer than ``time_limit`` seconds of wall time (a stall: its late point
    is not used; the solver's own time option, where it has one, stops it near the limit).
    ``info["solver_status"]`` gets the status; a failure with ``fallback=True`` also counts one
    ``info["fallbacks"]`` (the caller then applies its documented safe action); with
    ``fallback=False`` (the caller retries another way) it is counted in
    ``info["solver_failures"]`` only.
    """
    start = time.perf_counter()
    try:
        raw, ok, status = solve()
        x = np.asarray(raw, dtype=float) if raw is not None else None
        status = str(status)
    except Exception as exc:  # noqa: BLE001 - any solver fault is a failure, never a crash
        x, ok, status = None, False, f"error: {type(exc).__name__}: {exc}"
    elapsed = time.perf_counter() - start
    reason = _reject(x, ok, status, shape, lower, upper, violation, tol, violation_tol)
    if time_limit is not None and elapsed > time_limit:
        reason = f"time limit: the solve took {elapsed:.3g} s > {time_limit:.3g} s ({reason or status})"
    if reason is None:
        info["solver_status"] = status
        return x
    info["solver_failures"] = info.get("solver_failures", 0) + 1
    if fallback:
        record_fallback(info, reason)
    else:
        info["solver_status"] = reason
    return None


def row_violation(values: Any, lower: Any, upper: Any) -> float:
    """Largest violation of ``lower <= values <= upper`` (0 when satisfied; inf if not finite)."""
    v = np.asarray(values, dtype=float).ravel()
    if not np.all(np.isfinite(v)):
        return math.inf
    excess = np.maximum(np.asarray(lower, dtype=float) - v, v - np.asarray(upper, dtype=float))
    return float(max(0.0, excess.max())) if excess.size else 0.0


def _reject(x, ok, status, shape, lower, upper, violation, tol, violation_tol) -> str | None:
    """Why the point ``x`` of a solve must not be used (``None``: it can be)."""
    if x is None or not ok:
        return status if status.startswith("error") else f"failed: {status}"
    if x.shape != tuple(shape):
        return f"wrong shape {x.shape}, expected {tuple(shape)} ({status})"
    if not np.all(np.isfinite(x)):
        return f"non-finite result ({status})"
    for bound, sign in ((lower, -1.0), (upper, 1.0)):
        if bound is not None:
            b = np.broadcast_to(np.asarray(bound, dtype=float), x.shape)
            excess = sign * (x - b) - tol * np.maximum(1.0, np.abs(np.where(np.isfinite(b), b, 0.0)))
            if np.any(excess > 0):
                return f"infeasible: bound violated by {float(np.max(excess)) + tol:.3g} ({status})"
    if violation is not None:
        v = float(violation(x))
        if not v <= violation_tol:
            return f"infeasible: constraint violated by {v:.3g} ({status})"
    return None


# ---------------------------------------------------------------------------------------------
# the interface and the two trivial policies
# ---------------------------------------------------------------------------------------------
@runtime_checkable
class Policy(Protocol):
    """Anything that maps a dict of observations to a dict of normalised actions."""

    info: dict[str, Any]

    def reset(self, seed: int | None = None) -> None: ...

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]: ...


class _AnyEnvPolicy:
    """A scripted policy for any PettingZoo env (no solver, no privileged state: it reads only
    ``possible_agents`` and the action spaces)."""

    name = ""
    cheap = True
    env_ids: tuple[str, ...] = ("platoon_v0", "cluster_v0", "servicing_v0", "formation_v0")

    @classmethod
    def supports(cls, env: Any) -> bool:
        return (isinstance(getattr(env, "possible_agents", None), list | tuple)
                and callable(getattr(env, "action_space", None)))

    @classmethod
    def supported(cls) -> str:
        return f"every satenv env {list(cls.env_ids)} (any PettingZoo ParallelEnv)"

    def __init__(self, env: Any, **options: Any) -> None:
        if options:
            raise BaselineError(f"{type(self).__name__}: unknown option(s) {sorted(options)}; accepted: []")
        if not self.supports(env):
            raise BaselineTypeError(f"{type(self).__name__} needs a PettingZoo env (possible_agents, "
                                    f"action_space(agent)), got {type(env).__name__}")
        self.shapes = {a: env.action_space(a).shape for a in env.possible_agents}
        self.info: dict[str, Any] = new_info(solver_status="no solver")

    def reset(self, seed: int | None = None) -> None:
        self.info = new_info(solver_status="no solver")


class ZeroPolicy(_AnyEnvPolicy):
    """No thrust: every agent coasts (the lower bound of every scoreboard)."""

    name = "zero"

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {a: np.zeros(self.shapes[a], dtype=np.float32) for a in observations}


class RandomPolicy(_AnyEnvPolicy):
    """Uniform random normalised thrust, seeded by ``reset(seed)``."""

    name = "random"

    def __init__(self, env: Any, **options: Any) -> None:
        super().__init__(env, **options)
        self._rng = np.random.default_rng()

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self._rng = np.random.default_rng(seed)

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {a: self._rng.uniform(-1.0, 1.0, self.shapes[a]).astype(np.float32) for a in observations}
