"""Recipes: held-out evaluation (:mod:`~satenv.training.recipes.heldout`), reading its system and
seeds from :mod:`satenv.tasks`; imitation (DAgger, its safe variants and shipping) is
:mod:`satenv.training.imitation`."""

from __future__ import annotations

import warnings

from satenv import tasks

__all__ = ["LEGACY_SYSTEM_NAMES", "system_name"]

LEGACY_SYSTEM_NAMES = {"cluster-case1": "cluster-li2022", "platoon-tplf30": "platoon-pereira2023"}
"""``--system`` names of earlier releases -> the system of :data:`satenv.tasks.SYSTEMS` (kept as
aliases for scripts)."""


def system_name(name: str) -> str:
    """A ``--system`` value as a :data:`satenv.tasks.SYSTEMS` name (an old name warns once and maps)."""
    if name in LEGACY_SYSTEM_NAMES:
        new = LEGACY_SYSTEM_NAMES[name]
        warnings.warn(f"--system {name} is the old name of the system {new!r}; use --system {new}",
                      FutureWarning, stacklevel=2)
        return new
    return tasks.system(name).name
