"""The filter's settings, its record and its errors."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from satenv.errors import SatenvError, SatenvTypeError

CONSTRAINTS: tuple[str, ...] = ("separation", "leader", "obstacle", "target", "keep-out", "los", "velocity",
                                 "angular-velocity")
"""Names of the constraint kinds (:attr:`SafetyRecord.active` indexes this tuple; -1: none)."""
_KIND = {name: k for k, name in enumerate(CONSTRAINTS)}
_BIG = 1e30
_ROW_TOL = 1e-12      # a proposal within this of a row (its own units: m, m/s, rad/s) passes unchanged
_QP_TOL = 1e-7        # a QP point may violate a row / the box by this much
_FLOOR = 0.05         # braking authority never below this fraction of the nominal (drift-heavy pairs)
MIN_MARGIN = 1e-9
"""The smallest ``margin``, ``los_margin`` and ``velocity_margin`` a :class:`SafetyConfig` takes: a
margin below it is lost in the float rounding of the gaps it inflates (km-scale distances carry
relative errors near 1e-13) and would only look like a margin."""


class SafetyError(SatenvError):
    """Bad input to the safety filter (a ``ValueError``): the message names the field."""


class SafetyTypeError(SafetyError, SatenvTypeError):
    """Input of the wrong type to the safety filter (a ``TypeError``)."""


class SafetyWarning(UserWarning):
    """The filter was asked for where it enforces less than one may expect (e.g. no separation)."""


# ---------------------------------------------------------------------------------------------
# config and record
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SafetyConfig:
    """The filter's settings (validated; unknown options are rejected by :meth:`from_options`).

    Attributes:
        margin: each separation distance ``D`` is inflated to ``(1 + margin) D`` (> 0).
        los_margin: half-space (LOS cone) margin [m] (> 0).
        velocity_margin: velocity bounds tightened to ``(1 - velocity_margin) V`` (in (0, 1)).
        gamma: discrete barrier rate in (0, 1]: ``h^+ >= (1 - gamma) h`` (1: only keep brakeable).
        penalty: reward penalty per unit ``|du|`` in the filtered envs (>= 0; 0: none).
    """

    margin: float = 0.02
    los_margin: float = 0.05
    velocity_margin: float = 0.02
    gamma: float = 1.0
    penalty: float = 0.0

    def __post_init__(self) -> None:
        limits = {"margin": (0.0, math.inf, False), "los_margin": (0.0, math.inf, False),
                  "velocity_margin": (0.0, 1.0, False), "gamma": (0.0, 1.0, True),
                  "penalty": (0.0, math.inf, None)}
        for name, (low, high, high_ok) in limits.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise SafetyTypeError(f"SafetyConfig.{name} must be a real number, got {value!r:.40}")
            try:
                v = float(value)
            except OverflowError:   # an int beyond the float range, e.g. 10**400
                v = math.inf
            ok = (math.isfinite(v) and (v >= low if high_ok is None else v > low)
                  and (v <= high if high_ok else v < high))
            if not ok:
                rng = (f">= {low:g}" if high_ok is None else f"> {low:g}") + (
                    "" if high == math.inf else f" and {'<=' if high_ok else '<'} {high:g}")
                raise SafetyError(f"SafetyConfig.{name} must be finite and {rng}, got {value!r:.40}")
            if name.endswith("margin") and v < MIN_MARGIN:
                raise SafetyError(f"SafetyConfig.{name} must be >= MIN_MARGIN = {MIN_MARGIN:g} (a smaller margin "
                                  f"is lost in float rounding), got {value!r:.40}")
            object.__setattr__(self, name, v)

    @classmethod
    def from_options(cls, config: SafetyConfig | None = None, **options: Any) -> SafetyConfig:
        """``config`` (default ``SafetyConfig()``) with ``options`` replaced; unknown keys rejected."""
        if config is not None and not isinstance(config, SafetyConfig):
            raise SafetyTypeError(f"config must be a SafetyConfig or None, got {type(config).__name__}")
        known = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(options) - set(known))
        if unknown:
            raise SafetyError(f"safety filter: unknown option(s) {unknown}; accepted: {known}")
        return dataclasses.replace(config or cls(), **options)


@dataclass(frozen=True)
class SafetyRecord:
    """What the filter did, per copy and agent ``(B, M)``.

    ``intervened`` (the action changed), ``delta`` ``|du|`` (Euclidean norm of the change of the
    normalised action the env applies: the proposal clipped to the action box first, so it is
    finite and at most the box's diameter for any finite proposal), ``infeasible`` (QP infeasible or
    failed: the backup action was applied),
    ``active`` (index into :data:`CONSTRAINTS` of the binding constraint, -1 when none).
    """

    intervened: np.ndarray
    delta: np.ndarray
    infeasible: np.ndarray
    active: np.ndarray

    @property
    def active_names(self) -> np.ndarray:
        """:attr:`active` as names (``""`` when none), ``(B, M)`` object array."""
        names = np.array(("",) + CONSTRAINTS, dtype=object)
        return names[self.active + 1]

    def infos(self) -> dict[str, np.ndarray]:
        """The record as info arrays ``safety_intervened``, ``safety_delta``,
        ``safety_infeasible``, ``safety_active`` (names)."""
        return {"safety_intervened": self.intervened, "safety_delta": self.delta,
                "safety_infeasible": self.infeasible, "safety_active": self.active_names}
