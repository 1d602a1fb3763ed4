"""An env whose ``step`` filters the actions first (``safety_filter=True`` on ``satenv.make``).

:class:`SafetyFilterWrapper` is a PettingZoo ``BaseParallelWrapper``, as Gymnasium modifies an
env: it delegates everything to the env it wraps (``unwrapped`` gives that env) and only filters
the actions in :meth:`~SafetyFilterWrapper.step`. Code that asks for a satenv env with
``isinstance`` reads ``env.unwrapped`` (``satenv.vector.SatVectorEnv``, ``satenv.gym_env``); the
baselines read the class-level ``metadata`` of ``type(env)``, which
:func:`satenv.perturbations.wrapper_class` gives the wrapper per env class.
"""

from __future__ import annotations

from typing import Any

from pettingzoo.utils.wrappers import BaseParallelWrapper

from satenv.perturbations import UncertaintyBounds, wrapper_class
from satenv.safety.config import SafetyConfig, SafetyTypeError
from satenv.safety.core import SafetyFilter

__all__ = ["SafetyFilterWrapper", "filtered_env", "safety_config"]


class SafetyFilterWrapper(BaseParallelWrapper):
    """``env`` with its actions filtered at every ``step`` by :attr:`safety` (a
    :class:`SafetyFilter`): per-agent infos get the record (``safety_*``), rewards
    ``- penalty * |du|``. Build it with :func:`filtered_env`."""

    def __init__(self, env: Any, config: SafetyConfig | None = None, *,
                 bounds: UncertaintyBounds | None = None, **options: Any) -> None:
        super().__init__(env)
        self.safety = SafetyFilter(env, config, bounds=bounds, **options)
        self.metadata = env.metadata

    def step(self, actions: dict[str, Any]):
        env = self.env
        if not env.agents:
            return env.step(actions)
        safe, rec = self.safety.filter(env._action_array(actions))
        obs, rewards, terms, truncs, infos = env.step(dict(zip(env.possible_agents, safe, strict=True)))
        pen = self.safety.config.penalty
        extra = {k: v[0].tolist() for k, v in rec.infos().items()}
        for i, agent in enumerate(env.possible_agents):
            infos[agent].update({k: v[i] for k, v in extra.items()})
            if pen:
                rewards[agent] -= pen * extra["safety_delta"][i]
        return obs, rewards, terms, truncs, infos

    def __repr__(self) -> str:
        return f"SafetyFilterWrapper<{self.env!r}>"


def filtered_env(env: Any, config: SafetyConfig | None = None, *, bounds: UncertaintyBounds | None = None,
                 **options: Any) -> SafetyFilterWrapper:
    """``env`` (a ``satenv.make`` env) wrapped so that its actions are filtered at every ``step``
    (:class:`SafetyFilterWrapper`; ``config``, ``bounds`` and ``options`` as for
    :class:`SafetyFilter`)."""
    return wrapper_class(SafetyFilterWrapper, type(env))(env, config, bounds=bounds, **options)


def safety_config(value: Any) -> SafetyConfig:
    """The config of a ``safety_filter=`` argument: ``True`` (defaults) or a :class:`SafetyConfig`."""
    if value is True:
        return SafetyConfig()
    if isinstance(value, SafetyConfig):
        return value
    raise SafetyTypeError(f"safety_filter must be True, False or a satenv.safety.SafetyConfig, got {value!r}")
