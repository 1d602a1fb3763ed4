"""``"j2_drag"`` against an independent DOP853 truth with its own drag model (differential drag)."""

import math

import numpy as np
import truth as T
from scipy.integrate import solve_ivp

from satenv import dynamics as sd

RHO0, H0, SCALE_H = 6.967e-13, 500e3, 63.822e3   # exponential atmosphere [kg/m^3, m, m]
OMEGA_E = 7.2921159e-5
B_CHIEF, B_DEPUTY = 0.01, 0.03                    # C_d A / m [m^2/kg]: differential drag


def _truth_acc(r, v, ballistic):
    """J2 gravity + drag written independently of satenv (co-rotating exponential atmosphere)."""
    v_air = v - np.array([-OMEGA_E * r[1], OMEGA_E * r[0], 0.0])
    rho = RHO0 * math.exp(-(math.sqrt(r @ r) - T.RE - H0) / SCALE_H)
    return T.kepler_acc(r) + T.j2_acc(r) - 0.5 * rho * ballistic * math.sqrt(v_air @ v_air) * v_air


def _propagate(rv0, ballistic, t_end):
    def rhs(_t, s):
        return np.concatenate([s[3:], _truth_acc(s[:3], s[3:], ballistic)])

    sol = solve_ivp(rhs, (0.0, t_end), rv0, method="DOP853", rtol=1e-12,
                    atol=np.r_[np.full(3, 1e-6), np.full(3, 1e-9)])
    assert sol.success, sol.message
    return sol.y[:, -1]


def test_j2_drag_matches_independent_truth_and_differential_drag_effect():
    orbit = sd.Orbit(a=T.RE + 500e3, i=math.radians(51.6))
    x0 = np.array([[0.0, 1000.0, 0.0, 0.0, 0.0, 0.0], [100.0, 0.0, 50.0, 0.0, -2 * orbit.n * 100, 0.0]])
    dt, steps = 10.0, round(orbit.period / 10.0)
    chief0 = orbit.rv
    acc0 = _truth_acc(chief0[:3], chief0[3:], B_CHIEF)
    deps0 = T.lvlh_to_eci(chief0, acc0, x0)
    chief = _propagate(chief0, B_CHIEF, steps * dt)
    deps = np.array([_propagate(d, B_DEPUTY, steps * dt) for d in deps0])
    truth = T.eci_to_lvlh(chief, _truth_acc(chief[:3], chief[3:], B_CHIEF), deps)
    no_drag = T.truth_relative("j2", x0, chief0, np.array([0.0, steps * dt]))[-1]

    force = sd.ForceModel(j2=True, drag=True, ballistic_chief=B_CHIEF, ballistic_deputy=B_DEPUTY)
    ours = sd.simulate("j2_drag", x0, orbit=orbit, dt=dt, steps=steps, force=force)[-1]
    err = np.linalg.norm(ours[:, :3] - truth[:, :3], axis=-1)
    effect_truth = np.linalg.norm(truth[:, :3] - no_drag[:, :3], axis=-1)
    ours_j2 = sd.simulate("j2", x0, orbit=orbit, dt=dt, steps=steps)[-1]
    effect_ours = np.linalg.norm(ours[:, :3] - ours_j2[:, :3], axis=-1)
    print(f"\nj2_drag max position error {err.max():.3e} m; differential drag effect "
          f"{effect_truth} m (truth) vs {effect_ours} m (satenv)")
    assert err.max() <= 0.01
    assert effect_truth.min() > 1.0  # a real effect, far above the truth's noise
    np.testing.assert_allclose(effect_ours, effect_truth, rtol=0.01)
