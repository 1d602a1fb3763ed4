"""``satenv.baselines.make("shield", env, policy=...)``: any policy filtered by :mod:`satenv.safety`.

The wrapped policy keeps its ``reset`` / ``act`` / ``info``; the filter changes an action only
when it would lead to a violation (:class:`satenv.safety.Shield`), reading the state the policy
reads (under navigation error: the estimate) with the nominal model and the declared bounds.
``info`` adds ``safety_interventions``, ``safety_delta`` (sum of ``|du|``), ``safety_infeasible``
and ``safety_steps`` since ``reset``.
``policy`` may be a policy object or a registered baseline's name (built for the same env);
every other option is a :class:`satenv.safety.SafetyConfig` field.
"""

from __future__ import annotations

from typing import Any

from satenv.baselines.base import BaselineError, BaselineTypeError, is_satenv_env
from satenv.safety import SafetyError
from satenv.safety import Shield as _Shield

__all__ = ["Shield"]


class Shield(_Shield):
    """:class:`satenv.safety.Shield` with the baseline class surface (``supports``, ``env_ids``)."""

    name = "shield"
    cheap = True
    env_ids: tuple[str, ...] = ("platoon_v0", "cluster_v0", "servicing_v0", "formation_v0")

    @classmethod
    def supports(cls, env: Any) -> bool:
        return is_satenv_env(env) and type(env).metadata["name"] in cls.env_ids

    @classmethod
    def supported(cls) -> str:
        return f"satenv envs {list(cls.env_ids)} (with policy=...)"

    def __init__(self, env: Any, policy: Any = None, **options: Any) -> None:
        if not is_satenv_env(env):
            raise BaselineTypeError(f"Shield needs a satenv env (satenv.make(...)), got {type(env).__name__}")
        if policy is None:
            raise BaselineError("Shield: option policy is required (a policy object or a baseline name)")
        if isinstance(policy, str):
            from satenv.baselines.registry import make

            policy = make(policy, env)
        try:
            super().__init__(env, policy, **options)
        except SafetyError as exc:
            raise (BaselineTypeError if isinstance(exc, TypeError) else BaselineError)(str(exc)) from None
