"""The policy interface shared by scripted baselines and learned policies.

A policy has ``reset(seed=None)`` and ``act(observations) -> actions`` (dicts keyed by agent,
actions normalised to ``[-1, 1]^3``), and an ``info`` dict with diagnostics such as
``"fallbacks"`` (solver failures replaced by a safe action, counted since ``reset``) and
``"solve_ms"`` (per-decision solve times).
"""

from __future__ import annotations

from dataclasses import fields
from typing import Any, Protocol, TypeVar, runtime_checkable

import numpy as np

C = TypeVar("C")


def config_from_options(config_cls: type[C], options: dict[str, Any], owner: str) -> C:
    """Build a baseline's frozen config dataclass from keyword options, rejecting unknown ones."""
    known = {f.name for f in fields(config_cls)}
    unknown = sorted(set(options) - known)
    if unknown:
        raise ValueError(f"{owner}: unknown option(s) {unknown}; accepted: {sorted(known)}")
    return config_cls(**options)


@runtime_checkable
class Policy(Protocol):
    """Anything that maps a dict of observations to a dict of normalised actions."""

    info: dict[str, Any]

    def reset(self, seed: int | None = None) -> None: ...

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]: ...


class ZeroPolicy:
    """No thrust: every agent coasts (the lower bound of every scoreboard)."""

    name = "zero"

    def __init__(self, env: Any) -> None:
        self.shapes = {a: env.action_space(a).shape for a in env.possible_agents}
        self.info: dict[str, Any] = {}

    def reset(self, seed: int | None = None) -> None:
        self.info = {"fallbacks": 0}

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {a: np.zeros(self.shapes[a], dtype=np.float32) for a in observations}


class RandomPolicy:
    """Uniform random normalised thrust, seeded by ``reset(seed)``."""

    name = "random"

    def __init__(self, env: Any) -> None:
        self.shapes = {a: env.action_space(a).shape for a in env.possible_agents}
        self.info: dict[str, Any] = {}
        self._rng = np.random.default_rng()

    def reset(self, seed: int | None = None) -> None:
        self._rng = np.random.default_rng(seed)
        self.info = {"fallbacks": 0}

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {a: self._rng.uniform(-1.0, 1.0, self.shapes[a]).astype(np.float32) for a in observations}
