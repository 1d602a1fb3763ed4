"""Bounded disturbance accelerations (LVLH, m/s^2)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

LI2022_PHASES = (np.pi / 3, -2 * np.pi / 3, np.pi / 2)


def sinusoid_disturbance(t, amplitude: float, omega: float = 0.02,
                         phases: tuple[float, float, float] = LI2022_PHASES) -> np.ndarray:
    """li2022 §4: ``w = w_bar [sin(0.02 t + pi/3), sin(0.02 t - 2pi/3), sin(0.02 t + pi/2)]``.

    ``t`` may be an array; returns ``(*t.shape, 3)``. Each component is bounded by ``amplitude``.
    """
    t = np.asarray(t, dtype=float)
    return amplitude * np.sin(omega * t[..., None] + np.asarray(phases))


@dataclass(frozen=True)
class BoundedRandomDisturbance:
    """Seeded random disturbance, uniform in the ball of radius ``amplitude`` [m/s^2].

    Draws come from the generator passed to :meth:`sample`, so the env's own
    ``np.random.Generator`` controls them (no global RNG).
    """

    amplitude: float

    def __post_init__(self) -> None:
        if not np.isfinite(self.amplitude) or self.amplitude < 0:
            raise ValueError(f"amplitude must be finite and >= 0, got {self.amplitude!r}")

    def sample(self, rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        """Draw disturbances of shape ``(*shape, 3)``."""
        direction = rng.normal(size=(*shape, 3))
        direction /= np.maximum(np.linalg.norm(direction, axis=-1, keepdims=True), 1e-12)
        radius = self.amplitude * rng.random(size=(*shape, 1)) ** (1.0 / 3.0)
        return direction * radius
