"""A policy folder both ways: the network alone and as shipped, on the same seeds.

Every learned policy is reported both ways (:mod:`satenv.training.card`):

* :data:`NETWORK_ALONE` — ``satenv.training.load(folder, env=env, shielded=False)``;
* :data:`AS_SHIPPED` — ``satenv.training.load(folder, env=env)``: behind ``satenv.safety.shield``
  with the options of the folder's ``env.json`` ``"safety_filter"``. A folder shipped without the
  filter is its network alone as shipped: one policy, the same episodes both ways.

:func:`policy` builds one way, :func:`evaluate` runs both on seeds and returns their episode
records (:func:`satenv.scoring.episode_record`); ``satenv.bench.safety_alone``, the scoreboard's
``trained:`` entries and the card's variant names all come from here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from satenv.errors import SatenvError, SatenvTypeError

__all__ = ["AS_SHIPPED", "NETWORK_ALONE", "VARIANTS", "evaluate", "policy", "ships_filtered"]

NETWORK_ALONE = "network alone"
"""The network by itself (``satenv.training.load(..., shielded=False)``)."""

AS_SHIPPED = "network + filter"
"""The folder as shipped: behind the safety filter, with its options, when it ships with it."""

VARIANTS = (NETWORK_ALONE, AS_SHIPPED)
"""The two ways every policy is reported."""

Episodes = Callable[[Any, Any, Sequence[int], str], list[dict[str, Any]]]
"""``episodes(env, policy, seeds, variant)``: the episode records of one way (e.g. a resumable cache)."""


def policy(folder: str | Path, env: Any, variant: str = AS_SHIPPED, *, filter_defaults: bool = False) -> Any:
    """The policy of ``folder`` for ``env``, one of :data:`VARIANTS`: ``satenv.training.load(folder,
    env=env, shielded=variant == AS_SHIPPED)``. With ``filter_defaults``, :data:`AS_SHIPPED` of a folder
    shipped without the filter is its network behind ``satenv.safety.shield`` at the filter's defaults
    (e.g. a training checkpoint flown behind the filter)."""
    if variant not in VARIANTS:
        raise SatenvError(f"variant must be one of {list(VARIANTS)}, got {variant!r}")
    if not isinstance(filter_defaults, bool):
        raise SatenvTypeError(f"filter_defaults must be a bool, got {filter_defaults!r:.40}")
    from satenv.training.policy import load

    if variant == AS_SHIPPED and filter_defaults and not ships_filtered(folder):
        from satenv.safety import shield

        return shield(load(folder, env=env, shielded=False), env)
    return load(folder, env=env, shielded=variant == AS_SHIPPED)


def ships_filtered(folder: str | Path) -> bool:
    """Whether ``folder`` ships behind the safety filter (its ``env.json`` has ``"safety_filter"``)."""
    from satenv.training.policy import policy_folder
    from satenv.training.trust import read_json

    meta = read_json(policy_folder(folder), "env.json")
    return isinstance(meta, dict) and meta.get("safety_filter") is not None


def _run_episodes(env: Any, pol: Any, seeds: Sequence[int], variant: str) -> list[dict[str, Any]]:
    from satenv.scoring import run_episodes

    return run_episodes(env, pol, seeds)


def evaluate(folder: str | Path, env: Any, seeds: Sequence[int], *, shipped_seeds: int | None = None,
             episodes: Episodes = _run_episodes) -> dict[str, list[dict[str, Any]]]:
    """``{variant: episode records}`` of ``folder`` on ``env``: the network alone on ``seeds``, as
    shipped on the first ``shipped_seeds`` of them (all when ``None``). A folder shipped without
    the filter runs once: as shipped is the network alone, its records on those seeds."""
    seeds = [int(s) for s in seeds]
    shipped = seeds if shipped_seeds is None else seeds[:shipped_seeds]
    out = {NETWORK_ALONE: episodes(env, policy(folder, env, NETWORK_ALONE), seeds, NETWORK_ALONE)}
    if ships_filtered(folder):
        out[AS_SHIPPED] = episodes(env, policy(folder, env, AS_SHIPPED), shipped, AS_SHIPPED)
    else:
        keep = set(shipped)
        out[AS_SHIPPED] = [e for e in out[NETWORK_ALONE] if e["seed"] in keep]
    return out
