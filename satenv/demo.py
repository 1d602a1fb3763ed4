"""A one-minute demo: one deputy 1 km behind a 500 km, 51.6 deg chief under every model.

Run ``python -m satenv.demo``. Prints the deputy's LVLH position after one orbit per model,
and the J2 and drag differential effects.
"""

from __future__ import annotations

import math

import numpy as np

from satenv.dynamics import MODELS, R_EARTH, Orbit, simulate


def main() -> None:
    orbit = Orbit.circular(R_EARTH + 500e3, i=math.radians(51.6))
    x0 = np.array([[100.0, 1000.0, 50.0, 0.0, -2.0 * orbit.n * 100.0, 0.0]])
    steps = round(orbit.period / 10.0)
    print(f"chief: circular {orbit.a / 1e3:.1f} km, i = 51.6 deg, period {orbit.period:.0f} s")
    print("deputy x0 (LVLH) = [100, 1000, 50] m, vy0 = -2 n x0 (no along-track drift in CW)")
    print(f"{'model':>10} | {'x [m]':>12} {'y [m]':>12} {'z [m]':>12}   after one orbit")
    final = {}
    for model in MODELS:
        final[model] = simulate(model, x0, orbit=orbit, dt=10.0, steps=steps)[-1, 0, :3]
        print(f"{model:>10} | " + " ".join(f"{v:12.4f}" for v in final[model]))
    print(f"J2 differential effect (j2 - nonlinear): {np.linalg.norm(final['j2'] - final['nonlinear']):.4f} m")
    print(f"drag differential effect (j2_drag - j2): {np.linalg.norm(final['j2_drag'] - final['j2']):.6f} m")


if __name__ == "__main__":
    main()
