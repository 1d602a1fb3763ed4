"""Scenario presets: frozen, validated dataclasses in SI units, one module per env family."""

from .platoon import PRESETS as PLATOON_PRESETS
from .platoon import PlatoonScenario, resolve_scenario, sample_initial_state

__all__ = ["PLATOON_PRESETS", "PlatoonScenario", "resolve_scenario", "sample_initial_state"]
