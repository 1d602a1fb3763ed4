"""An env whose ``step`` filters the actions first (``safety_filter=True`` on ``satenv.make``)."""

from __future__ import annotations

from typing import Any

from satenv.safety.config import SafetyConfig, SafetyTypeError
from satenv.safety.core import SafetyFilter


# ---------------------------------------------------------------------------------------------
# filtered envs (safety_filter=True on satenv.make / make_vec / satenv.torchrl.make_env)
# ---------------------------------------------------------------------------------------------
def _filtered_class(cls: type) -> type:
    """The subclass of a satenv env class whose ``step`` filters the actions first: per-agent
    infos get the record (``safety_*``), rewards ``- penalty * |du|``."""

    def step(self, actions):
        if not self.agents:
            return cls.step(self, actions)
        safe, rec = self.safety.filter(self._action_array(actions))
        obs, rewards, terms, truncs, infos = cls.step(self, dict(zip(self.possible_agents, safe, strict=True)))
        pen = self.safety.config.penalty
        extra = {k: v[0].tolist() for k, v in rec.infos().items()}
        for i, agent in enumerate(self.possible_agents):
            infos[agent].update({k: v[i] for k, v in extra.items()})
            if pen:
                rewards[agent] -= pen * extra["safety_delta"][i]
        return obs, rewards, terms, truncs, infos

    if cls not in _FILTERED:
        _FILTERED[cls] = type(f"Filtered{cls.__name__}", (cls,), {"step": step, "__doc__": cls.__doc__,
                                                                  "__module__": __name__})
    return _FILTERED[cls]


_FILTERED: dict[type, type] = {}


def __getattr__(name: str) -> type:
    """``satenv.safety.Filtered<EnvClass>`` (the class :func:`filtered_env` gives an env), so that a
    filtered env pickles by reference (e.g. into a Gymnasium ``AsyncVectorEnv`` worker)."""
    if name.startswith("Filtered"):
        import importlib

        import satenv

        for env_id in satenv.ENV_IDS:
            cls = getattr(importlib.import_module(f"satenv.envs.{env_id}"), name[len("Filtered"):], None)
            if isinstance(cls, type):
                return _filtered_class(cls)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def filtered_env(env: Any, config: SafetyConfig | None = None, **options: Any) -> Any:
    """``env`` (a ``satenv.make`` env) with its actions filtered at every ``step`` (the same
    object, its class a filtered subclass: every attribute and check of the env still holds)."""
    filt = SafetyFilter(env, config, **options)
    env.__class__ = _filtered_class(type(env))
    env.safety = filt
    return env


def safety_config(value: Any) -> SafetyConfig:
    """The config of a ``safety_filter=`` argument: ``True`` (defaults) or a :class:`SafetyConfig`."""
    if value is True:
        return SafetyConfig()
    if isinstance(value, SafetyConfig):
        return value
    raise SafetyTypeError(f"safety_filter must be True, False or a satenv.safety.SafetyConfig, got {value!r}")
