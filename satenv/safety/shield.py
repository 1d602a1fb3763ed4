"""A policy behind the filter: :class:`Shield` (same ``reset`` / ``act`` / ``info`` as any policy)."""

from __future__ import annotations

from typing import Any

import numpy as np

from satenv.safety.config import SafetyConfig, SafetyTypeError
from satenv.safety.core import SafetyFilter, _real_array


class Shield:
    """A policy filtered by :class:`SafetyFilter` for the env it acts on (same ``reset`` /
    ``act`` / ``info`` as any policy). It reads the state the env holds when the policy acts, as the
    policy does (under a perturbation's navigation error: the estimate), and plans with the
    nominal model and the env's declared bounds (:class:`SafetyFilter`). An action that is safe is
    returned as the policy gave it (the same object); ``info`` adds ``safety_interventions``,
    ``safety_delta`` (sum of ``|du|``), ``safety_infeasible`` (agent-steps) and ``safety_steps`` since
    :meth:`reset`, and ``safety_record`` (the last :class:`SafetyRecord`).
    """

    name = "shield"

    def __init__(self, env: Any, policy: Any, config: SafetyConfig | None = None, **options: Any) -> None:
        if not (callable(getattr(policy, "act", None)) and callable(getattr(policy, "reset", None))):
            raise SafetyTypeError("shield: policy must have reset() and act(observations), "
                                  f"got {type(policy).__name__}")
        self.filter = SafetyFilter(env, config, **options)
        self.env = env
        self.policy = policy
        self.agents = list(env.possible_agents)
        self._counts = _zero_counts()

    @property
    def info(self) -> dict[str, Any]:
        return {**getattr(self.policy, "info", {}), **self._counts}

    def __getattr__(self, name: str) -> Any:
        """Anything else is the wrapped policy's (e.g. a learned policy's ``obs_shape``)."""
        if name in ("policy", "filter", "_counts"):
            raise AttributeError(name)
        return getattr(self.policy, name)

    def reset(self, seed: int | None = None) -> None:
        self.policy.reset(seed)
        self._counts = _zero_counts()

    def act(self, observations: dict[str, Any]) -> dict[str, Any]:
        proposed = self.policy.act(observations)
        live = [a for a in self.agents if a in proposed]
        if len(live) != len(self.agents):   # an ended episode: nothing to filter
            return proposed
        safe, rec = self.filter.filter(np.stack([_real_array(f"action of {a}", proposed[a]) for a in live]))
        c = self._counts
        c["safety_interventions"] += int(rec.intervened.sum())
        c["safety_delta"] += float(rec.delta.sum())
        c["safety_infeasible"] += int(rec.infeasible.sum())
        c["safety_steps"] += 1
        c["safety_record"] = rec
        return {a: (safe[i].astype(np.float32) if rec.intervened[0, i] else proposed[a])
                for i, a in enumerate(live)}


def _zero_counts() -> dict[str, Any]:
    return {"safety_interventions": 0, "safety_delta": 0.0, "safety_infeasible": 0, "safety_steps": 0,
            "safety_record": None}


def shield(policy: Any, env: Any, config: SafetyConfig | None = None, **options: Any) -> Shield:
    """``policy`` filtered for ``env``: a :class:`Shield`."""
    return Shield(env, policy, config, **options)
