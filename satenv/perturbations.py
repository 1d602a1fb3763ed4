"""Named perturbations a task is evaluated under: navigation error, actuator degradation, a
stronger disturbance, model mismatch.

    from satenv import tasks, perturbations
    env = perturbations.make_env(tasks.get("cluster-case1-random"), "nav-1m")

**Planners never see the truth.** A :class:`Perturbation` changes the truth, never the nominal
model: every filter, controller and expert plans with the task's nominal env, read through one
accessor, :func:`nominal` (``nominal(env).scenario``, ``nominal(env).core`` for its model), while
the core integrates the perturbed physics (``truth`` overrides: a weaker thruster is the truth's
smaller ``u_max`` under the nominal one the commands are normalised by) and the ``infos`` (what
the metrics score) are the truth's. **Navigation error** is what everyone on board reads: between
two steps the core's agent states are replaced by a noisy estimate (Gaussian, ``sigma_position``
[m] and ``sigma_velocity`` [m/s] per axis, drawn from the episode's seed), so the policy's
observation, ``env.state()``, the scripted controllers and the safety filter wrapped around a
policy (:class:`satenv.safety.Shield`) all see the same estimate; the truth is restored before the
physics of the next step. A controller that acts inside the step at the physics rate (the cluster's
inner-loop hook, the tube controller of ``satenv.baselines.TubeRDMPC``) reads the true sub-step
state plus the decision's navigation error, held over the decision: an estimate, never the truth.

**Declared bounds.** Each perturbation declares the :class:`UncertaintyBounds` a planner is told
(:func:`declared_bounds`), and a safety filter built on the env tightens its constraints by them
(:mod:`satenv.safety.margins`). A navigation system reports its error statistics, so the
navigation perturbations declare a bound: the radius that holds a 3-axis Gaussian error of the
declared sigma with probability :data:`NAV_BOUND_PROBABILITY` per draw. The truth changes
(thrust, disturbance, model, inertia) declare nothing: they are what a planner does not know, and
the board measures how it copes. A filter built into the env (``safety_filter=True`` in its
keywords) would run inside the truth's step and read the truth, so a perturbed env refuses it: the
filter goes around the policy instead (:func:`satenv.safety.shield`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
from pettingzoo.utils.wrappers import BaseParallelWrapper

from satenv.errors import SatenvError, SatenvTypeError

__all__ = ["NAV_BOUND_PROBABILITY", "PERTURBATIONS", "Perturbation", "PerturbationMismatchError", "PerturbedEnv",
           "UncertaintyBounds", "declared_bounds", "get", "make_env", "names", "nominal", "perturbed"]

NAV_SEED_KEY = 0x6E6176
"""Mixed with the episode seed to seed the navigation error (independent of the env's own draws)."""

NAV_BOUND_PROBABILITY = 0.999
"""The probability per draw that a navigation error lies within its declared bound."""


@dataclass(frozen=True)
class UncertaintyBounds:
    """What a planner is told it cannot see (all >= 0; zero: exact knowledge).

    Attributes:
        position: bound on the norm of one agent's position estimate error [m].
        velocity: bound on the norm of one agent's velocity estimate error [m/s].
        disturbance: bound on an unmodelled disturbance acceleration per agent [m/s^2] (beyond the
            nominal scenario's own disturbance).
        thrust: the fraction of the commanded acceleration that may be lost, in [0, 1).
    """

    position: float = 0.0
    velocity: float = 0.0
    disturbance: float = 0.0
    thrust: float = 0.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise SatenvTypeError(f"UncertaintyBounds.{f.name} must be a real number, got {v!r:.40}")
            high = 1.0 if f.name == "thrust" else math.inf
            if not (math.isfinite(float(v)) and 0.0 <= float(v) < high):
                raise SatenvError(f"UncertaintyBounds.{f.name} must be finite, >= 0"
                                  f"{' and < 1' if high == 1.0 else ''}, got {v!r:.40}")
            object.__setattr__(self, f.name, float(v))

    @property
    def exact(self) -> bool:
        """No uncertainty at all (the filter is then exactly the nominal one)."""
        return not (self.position or self.velocity or self.disturbance or self.thrust)


def navigation_bounds(sigma_position: float, sigma_velocity: float) -> UncertaintyBounds:
    """The bound on the norm of a 3-axis Gaussian error (sigma per axis) that holds with
    probability :data:`NAV_BOUND_PROBABILITY`: ``sigma sqrt(chi2_3^-1(p))`` (4.03 sigma)."""
    k = math.sqrt(_chi2_3_quantile(NAV_BOUND_PROBABILITY))
    return UncertaintyBounds(position=k * sigma_position, velocity=k * sigma_velocity)


def _chi2_3_quantile(p: float) -> float:
    """``chi2_3^-1(p)`` by bisection on the closed-form CDF ``erf(sqrt(x/2)) - sqrt(2x/pi) e^(-x/2)``."""
    lo, hi = 0.0, 100.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        cdf = math.erf(math.sqrt(mid / 2)) - math.sqrt(2 * mid / math.pi) * math.exp(-mid / 2)
        lo, hi = (mid, hi) if cdf < p else (lo, mid)
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class Perturbation:
    """One named perturbation: ``truth(scenario) -> overrides`` of the truth env's scenario (the
    nominal scenario stays what ``env.scenario`` shows), navigation error ``sigma_position`` [m]
    and ``sigma_velocity`` [m/s]; :attr:`bounds` is what it declares to a planner."""

    name: str
    description: str
    truth: Callable[[Any], Mapping[str, Any]] = field(default=lambda sc: {})
    sigma_position: float = 0.0
    sigma_velocity: float = 0.0

    @property
    def bounds(self) -> UncertaintyBounds:
        """The declared bounds: the navigation error's (module docstring), nothing else."""
        return navigation_bounds(self.sigma_position, self.sigma_velocity)


def _scaled_thrust(k: float) -> Callable[[Any], Mapping[str, Any]]:
    def truth(sc: Any) -> Mapping[str, Any]:
        u = np.asarray(sc.u_max, dtype=float) * k
        return {"u_max": float(u) if u.ndim == 0 else tuple(u.tolist())}
    return truth


def _scaled_inertia(k: float) -> Callable[[Any], Mapping[str, Any]]:
    return lambda sc: {"inertia": tuple(tuple(k * v for v in row) for row in np.asarray(sc.inertia).tolist())}


PERTURBATIONS: Mapping[str, Perturbation] = MappingProxyType({p.name: p for p in [
    Perturbation("nav-0.1m", "navigation error 0.1 m, 1 mm/s (1 sigma per axis), read by everyone on board",
                 sigma_position=0.1, sigma_velocity=0.001),
    Perturbation("nav-1m", "navigation error 1 m, 1 cm/s (1 sigma per axis), read by everyone on board",
                 sigma_position=1.0, sigma_velocity=0.01),
    Perturbation("thrust-80", "actuator degradation: 80 % of the commanded thrust is applied (after the "
                 "nominal saturation)", truth=_scaled_thrust(0.8)),
    Perturbation("disturbance-x2", "the disturbance force doubled",
                 truth=lambda sc: {"disturbance_force": 2.0 * sc.disturbance_force}),
    Perturbation("model-j2", "model mismatch: J2 truth (chief inclination 51.6 deg) under a CW nominal model",
                 truth=lambda sc: {"dynamics": "j2", **({"inclination": np.radians(51.6)}
                                                        if hasattr(sc, "inclination") else {})}),
    Perturbation("model-cw", "model mismatch the other way: CW truth under the nominal J2 + drag scenario",
                 truth=lambda sc: {"dynamics": "cw"}),
    Perturbation("inertia-x1.5", "model mismatch: true inertia 1.5x the nominal", truth=_scaled_inertia(1.5)),
    Perturbation("inertia-x0.5", "model mismatch: true inertia 0.5x the nominal", truth=_scaled_inertia(0.5)),
]})
"""Every perturbation by name; a task lists those that apply to it (``Task.perturbations``)."""


def names() -> tuple[str, ...]:
    return tuple(PERTURBATIONS)


class PerturbationMismatchError(SatenvError):
    """A perturbation that does not apply to an env (its scenario lacks the field it changes)."""


def get(name: str) -> Perturbation:
    if not isinstance(name, str) or name not in PERTURBATIONS:
        raise SatenvError(f"unknown perturbation {name!r:.80}; expected one of {list(PERTURBATIONS)}")
    return PERTURBATIONS[name]


class PerturbedEnv(BaseParallelWrapper):
    """A satenv ``ParallelEnv`` under one :class:`Perturbation` (see the module docstring).

    ``truth_env`` runs the perturbed physics; ``nominal_env`` is the task's nominal env (never
    stepped): what :func:`nominal` gives a planner, its scenario what ``env.scenario`` shows."""

    def __init__(self, truth_env: Any, perturbation: Perturbation, nominal_env: Any) -> None:
        super().__init__(truth_env)
        self.perturbation = perturbation
        self.nominal_env = nominal_env
        self.nominal_scenario = nominal_env.scenario
        self.metadata = {**truth_env.metadata, "perturbation": perturbation.name}
        self._truth: np.ndarray | None = None
        self._noise: np.ndarray | None = None
        self._nav_rng = np.random.default_rng(NAV_SEED_KEY)

    @property
    def scenario(self) -> Any:
        return self.nominal_scenario

    @property
    def unwrapped(self) -> Any:
        return self   # the state (the estimate) is read through this wrapper; the model: nominal()

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self.env, name)

    def _estimate(self, obs: dict[str, Any]) -> dict[str, Any]:
        """Install the navigation estimate in the core and observe it (no-op without nav error)."""
        p = self.perturbation
        if not (p.sigma_position or p.sigma_velocity) or not obs:
            return obs
        core = self.env.core
        self._truth = core.x.copy()
        noise = self._nav_rng.standard_normal(core.x[..., :6].shape)
        noise[..., :3] *= p.sigma_position
        noise[..., 3:6] *= p.sigma_velocity
        core.x[..., :6] += noise
        self._noise = noise
        noisy = core.observe()[0]
        return {a: noisy[i] for i, a in enumerate(self.env.possible_agents) if a in obs}

    def _restore(self) -> np.ndarray | None:
        """Put the truth back; the navigation error it replaces (``None`` when none was installed)."""
        if self._truth is None:
            return None
        noise = self._noise
        self.env.core.x[...] = self._truth
        self._truth = None
        return noise

    def reset(self, seed: int | None = None, options: dict | None = None):
        self._restore()
        self._nav_rng = np.random.default_rng([NAV_SEED_KEY, 0 if seed is None else int(seed)])
        obs, infos = self.env.reset(seed=seed, options=options)
        return self._estimate(obs), infos

    def step(self, actions: dict[str, Any]):
        noise = self._restore()
        with _estimated_inner_loop(self.env.core, noise):
            obs, rewards, terms, truncs, infos = self.env.step(actions)
        return self._estimate(obs), rewards, terms, truncs, infos

    def state(self) -> np.ndarray:
        return self.env.state()


class _EstimatedInnerLoop:
    """A physics-rate controller hook fed the true sub-step state plus the decision's navigation
    error (module docstring)."""

    def __init__(self, loop: Any, noise: np.ndarray) -> None:
        self.loop, self.noise = loop, noise

    def correction(self, t: np.ndarray, x: np.ndarray, chief: np.ndarray, u_cmd: np.ndarray) -> np.ndarray:
        estimate = x.copy()
        estimate[..., :6] += self.noise
        return self.loop.correction(t, estimate, chief, u_cmd)


@contextlib.contextmanager
def _estimated_inner_loop(core: Any, noise: np.ndarray | None) -> Any:
    """Within: the core's inner-loop hook (if any) reads the estimate; after: the hook as it was."""
    loop = getattr(core, "inner_loop", None)
    if loop is None or noise is None:
        yield
        return
    core.inner_loop = _EstimatedInnerLoop(loop, noise)
    try:
        yield
    finally:
        core.inner_loop = loop


def make_env(task: Any, perturbation: str | None, **overrides: Any) -> Any:
    """The task's env under the named perturbation (``None``: the nominal env), with
    ``overrides`` applied to both the nominal and the truth scenario; a perturbation that does not
    apply to the task's env is a :class:`satenv.errors.SatenvError` naming the task's perturbations."""
    try:
        return perturbed(lambda **kw: task.make_env(**{**overrides, **kw}), perturbation)
    except PerturbationMismatchError as err:
        raise PerturbationMismatchError(f"task {task.name!r}: {err}; its perturbations are "
                                        f"{list(task.perturbations)}") from None


def perturbed(build: Callable[..., Any], perturbation: str | None) -> Any:
    """``build(**scenario_overrides)`` (a satenv env) under the named perturbation: the nominal env
    is ``build()``, the truth ``build(**truth overrides)``."""
    nominal = build()
    if perturbation is None:
        return nominal
    p = get(perturbation)
    if getattr(nominal, "safety", None) is not None:
        raise SatenvError(f"perturbation {perturbation!r} with a filter built into the env (safety_filter=...): "
                          "that filter would run inside the truth and read it; build the env without it and wrap "
                          "the policy instead, satenv.safety.shield(policy, env), which plans with the nominal "
                          "model and reads the estimate")
    try:
        changes = p.truth(nominal.scenario)
    except AttributeError as err:   # the scenario has no such field: another system's perturbation
        raise PerturbationMismatchError(f"perturbation {perturbation!r} does not apply to this env (its "
                                        f"{type(nominal.scenario).__name__} has no {err.name!r})") from None
    truth = build(**changes)
    return _wrapper_class(type(truth))(truth, p, nominal)


def nominal(env: Any) -> Any:
    """The env a planner models (the one accessor every filter, controller and expert reads its
    scenario and model through): the nominal env of a perturbed env, else ``env`` itself."""
    return getattr(env, "nominal_env", env)


def declared_bounds(env: Any) -> UncertaintyBounds:
    """The :class:`UncertaintyBounds` an env declares to its planners (its perturbation's; none
    for a nominal env)."""
    p = getattr(env, "perturbation", None)
    return p.bounds if isinstance(p, Perturbation) else UncertaintyBounds()


def _wrapper_class(env_class: type) -> type:
    """:class:`PerturbedEnv` with the env class's ``metadata`` (what the baselines check)."""
    return wrapper_class(PerturbedEnv, env_class)


@functools.cache
def wrapper_class(wrapper: type, env_class: type) -> type:
    """``wrapper`` (a PettingZoo ``BaseParallelWrapper``) with ``env_class``'s class-level
    ``metadata``: the baselines read ``type(env).metadata["name"]``, which a wrapper's
    ``__getattr__`` cannot forward."""
    prefix = wrapper.__name__.removesuffix("Env").removesuffix("Wrapper")
    return type(f"{prefix}{env_class.__name__}", (wrapper,), {"metadata": env_class.metadata,
                                                               "__module__": wrapper.__module__})
