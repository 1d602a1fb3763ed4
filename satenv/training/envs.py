"""Building satenv envs for training by id (no learning library imported here).

``env_id`` is a satenv env id (``"platoon_v0"``, built with :func:`satenv.make`) or
``"package.module:callable"`` for an env defined elsewhere (e.g. a test fixture).
"""

from __future__ import annotations

from typing import Any

from satenv.envs.base import SatenvError, SatParallelEnv

__all__ = ["make_env", "env_version", "policy_env_meta"]


def make_env(env_id: str, **kwargs: Any) -> SatParallelEnv:
    """Build the PettingZoo env ``env_id`` with ``kwargs`` (module docstring)."""
    if not isinstance(env_id, str) or not env_id:
        raise SatenvError(f"env_id must be a non-empty string such as 'platoon_v0', got {env_id!r}")
    if ":" not in env_id:
        import satenv

        if env_id not in satenv.ENV_IDS:
            raise SatenvError(f"unknown env id {env_id!r}: use one of {list(satenv.ENV_IDS)} or "
                              "'package.module:callable'")
        return satenv.make(env_id, **kwargs)
    from satenv.baselines.registry import ResolveError, resolve

    try:
        factory = resolve(env_id)
    except ModuleNotFoundError as err:
        raise SatenvError(f"unknown env id {env_id!r}: cannot import {env_id.partition(':')[0]!r} ({err}); use a "
                          "satenv env id such as 'platoon_v0' or 'package.module:callable'") from None
    except ResolveError as err:
        raise SatenvError(f"unknown env id {env_id!r}: {err}") from None
    env = factory(**kwargs)
    if not isinstance(env, SatParallelEnv):
        raise SatenvError(f"env id {env_id!r} built a {type(env).__name__}; expected a "
                          "satenv.envs.base.SatParallelEnv subclass (it needs a batched core)")
    return env


def env_version(env_id: str) -> str:
    """The version suffix of an env id (``"platoon_v0"`` -> ``"v0"``), or ``""``."""
    tail = env_id.rsplit(":", 1)[-1].rsplit("_", 1)
    return tail[-1] if len(tail) == 2 and tail[-1].startswith("v") else ""


def policy_env_meta(env_id: str, env: SatParallelEnv, env_kwargs: dict[str, Any],
                    eval_env_kwargs: dict[str, Any]) -> dict[str, Any]:
    """The ``env.json`` of a policy folder: what it was trained on and is evaluated with."""
    import satenv

    agent = env.possible_agents[0]
    return {
        "env_id": env_id,
        "env_version": env_version(env_id),
        "env_name": env.metadata.get("name", type(env).__name__),
        "satenv_version": satenv.__version__,
        "env_kwargs": env_kwargs,
        "eval_env_kwargs": eval_env_kwargs,
        "agents": list(env.possible_agents),
        "observation_shape": list(env.observation_space(agent).shape),
        "action_shape": list(env.action_space(agent).shape),
        "parameter_sharing": True,
    }
