"""satenv.baselines.dmpc: the 1-hop DMPC (pereira2023) and the convex-step DMPC (pereira2022)."""

import numpy as np
import pytest

from satenv.baselines import BaselineError, BaselineTypeError
from satenv.baselines.dmpc import (
    DMPC,
    ConvexStepDMPC,
    DMPCConfig,
    OneHopDMPC,
    QPSolver,
    centralised_gain,
)
from satenv.dynamics import cw_matrices, prediction_matrices
from satenv.envs.platoon_v0 import parallel_env
from satenv.graph import make_topology
from satenv.scenarios.platoon import PRESETS, los_keepout_ok, pair_states

P23 = PRESETS["pereira2023"]
C23 = DMPCConfig.paper("pereira2023")


def _closed_form(scenario, x):
    k, kd = centralised_gain(scenario)
    e = scenario.graph.neighbourhood_error(x).ravel()
    e_d = np.tile(np.asarray(scenario.desired_error), C23.horizon * scenario.n_followers)
    return (-k @ e + kd @ e_d).reshape(scenario.n_followers, -1)


@pytest.mark.parametrize("topology", ["PLF", "BDL", "TPLF", "custom"])
def test_proposition3_jacobi_converges_to_centralised_closed_form(topology):
    rng = np.random.default_rng(1)
    if topology == "custom":  # a denser graph with a cycle: 1<->3, 2->1, 4 hears 1 and 2
        topology = np.array([[0, 1, 1, 0], [0, 0, 0, 0], [1, 0, 0, 0], [1, 1, 0, 0]])
    sc = P23.with_overrides(topology=topology)
    ctl = OneHopDMPC(sc, constrained=False, sigma=1e-9, max_iterations=5000, seed=7)
    x = sc.initial_array() + rng.normal(scale=[5, 5, 5, 0.5, 0.5, 0.5], size=(4, 6))
    u = ctl.solve(x)
    assert ctl.info["not_converged"] == 0
    ustar = _closed_form(sc, x)
    scale = np.abs(ustar).max()
    np.testing.assert_allclose(ctl.U, ustar, atol=1e-7 * scale)
    np.testing.assert_allclose(u, ustar[:, :3], atol=1e-7 * scale)


def test_closed_form_is_the_minimiser_of_the_summed_local_costs():
    """(25) must satisfy each agent's first-order condition (21) with the others' U fixed."""
    sc = P23.with_overrides(topology="BDL")
    x = sc.initial_array()
    ustar = _closed_form(sc, x)
    a, b = cw_matrices(sc.mean_motion, sc.dt)
    ca, cb = prediction_matrices(a, b, C23.horizon)
    q = np.tile(np.asarray(sc.state_weight), C23.horizon)
    q[-6:] = C23.terminal_weight
    w = np.tile(np.asarray(sc.input_weight), C23.horizon)
    topo = sc.graph
    e = topo.neighbourhood_error(x)
    ebar = np.tile(np.asarray(sc.desired_error), C23.horizon)
    for f in range(4):
        c = topo.gains[f]
        su = sum(ustar[i] for i in topo.neighbours(f))
        pred = ca @ e[f] + c * cb @ ustar[f] - cb @ su - c * ebar   # eq. 16 minus target
        grad = 2 * c * cb.T @ (q * pred) + 2 * w * ustar[f]         # d/dU_f of (18)
        assert np.abs(grad).max() < 1e-6 * np.abs(cb.T @ (q * (ca @ e[f]))).max()


def test_constrained_solution_respects_input_and_velocity_bounds():
    sc = P23.with_overrides(topology="BDL", v_max=3.0)
    ctl = OneHopDMPC(sc, seed=0)
    x = sc.initial_array()
    ctl.solve(x)
    assert ctl.info["fallbacks"] == 0
    assert np.all(np.abs(ctl.U) <= sc.u_max + 1e-6)
    # velocity rows of the predicted neighbourhood error, with the neighbours' final iterates
    a, b = cw_matrices(sc.mean_motion, sc.dt)
    ca, cb = prediction_matrices(a, b, C23.horizon)
    topo = sc.graph
    e = topo.neighbourhood_error(x)
    su = topo.adjacency @ ctl.U
    for f in range(4):
        c = topo.gains[f]
        pred = (ca @ e[f] + c * cb @ ctl.U[f] - cb @ su[f]).reshape(-1, 6)
        # the Jacobi loop stops at ||dU|| <= sigma, so allow the sigma-sized slack
        assert np.abs(pred[:, 3:]).max() <= c * sc.v_max + 0.5


def test_constrained_equals_unconstrained_when_bounds_are_inactive():
    sc = P23.with_overrides(u_max=1e6, v_max=1e6)
    x = sc.initial_array()
    a = OneHopDMPC(sc, sigma=1e-9, max_iterations=1000, seed=0)
    b = OneHopDMPC(sc, constrained=False, sigma=1e-9, max_iterations=1000, seed=0)
    np.testing.assert_allclose(a.solve(x), b.solve(x), rtol=1e-6, atol=1e-6)


def test_daqp_and_osqp_agree():
    sc = P23.with_overrides(topology="TPLF")
    x = sc.initial_array()
    a = OneHopDMPC(sc, solver="daqp", seed=3, sigma=1e-6)
    b = OneHopDMPC(sc, solver="osqp", seed=3, sigma=1e-6)
    np.testing.assert_allclose(a.solve(x), b.solve(x), atol=1e-3)


def test_random_initial_sequence_is_seeded_and_used():
    sc = P23.with_overrides(topology="BDL")
    x = sc.initial_array()
    # sigma huge: one Jacobi iteration from the random start, so the start matters (BDL couples)
    runs = {}
    for name, seed in (("a", 1), ("b", 1), ("c", 2)):
        ctl = OneHopDMPC(sc, seed=seed, sigma=1e9)
        ctl.solve(x)
        runs[name] = ctl.U
    np.testing.assert_array_equal(runs["a"], runs["b"])
    assert np.abs(runs["a"] - runs["c"]).max() > 1e-3


def test_shifted_warm_start():
    sc = P23
    ctl = OneHopDMPC(sc, seed=0, sigma=1e9)  # one iteration -> the warm start is observable
    ctl.solve(sc.initial_array())
    prev = ctl.U.copy()
    start = ctl._initial_iterate()
    np.testing.assert_array_equal(start[:, :-3], prev[:, 3:])
    np.testing.assert_array_equal(start[:, -3:], prev[:, -3:])
    ctl2 = OneHopDMPC(sc, seed=0, sigma=1e9, warm_start="previous")
    ctl2.solve(sc.initial_array())
    np.testing.assert_array_equal(ctl2._initial_iterate(), ctl2.U)


def test_infeasible_min_error_constraint_falls_back_without_crashing():
    # follower 1 sits 1 cm from where E_1 = 0 while (41) asks ||E_1|| >= 3 m at the next step
    x0 = P23.initial_array()
    x0[0, :3] = [0.01, 0.0, 0.0]
    sc = P23.with_overrides(initial_state=x0, min_error_constraint=True)
    ctl = OneHopDMPC(sc, seed=0)
    u = ctl.solve(x0)
    assert ctl.info["fallbacks"] > 0
    assert np.all(np.isfinite(u)) and np.all(np.abs(u) <= sc.u_max)
    assert np.all(np.abs(ctl.U) <= sc.u_max)


def test_min_error_constraint_keeps_the_error_outside_the_sphere_when_feasible():
    sc = P23.with_overrides(min_error_constraint=True)
    ctl = OneHopDMPC(sc, seed=0)
    a, b = cw_matrices(sc.mean_motion, sc.dt)
    x = sc.initial_array()
    for _ in range(60):
        x = x @ a.T + ctl.solve(x) @ b.T
        e = sc.graph.neighbourhood_error(x)
        assert np.all(np.linalg.norm(e[:, :3], axis=1) >= sc.graph.gains * sc.follower_radius - 1e-6)
    assert ctl.info["fallbacks"] == 0


def test_policy_interface_and_info():
    env = parallel_env()
    pol = DMPC(env, seed=0)
    obs, _ = env.reset(seed=0)
    pol.reset(seed=0)
    act = pol.act(obs)
    assert set(act) == set(env.agents)
    for a in act.values():
        assert a.shape == (3,) and a.dtype == np.float32 and np.all(np.abs(a) <= 1)
        assert env.action_space("follower_1").contains(a)
    env.step(act)
    pol.act(obs)
    assert len(pol.info["solve_ms"]) == 2 and pol.info["fallbacks"] == 0
    assert {"qp_ms", "iterations", "not_converged"} <= set(pol.info)
    # same seed -> same actions
    pol.reset(seed=0)
    env.reset(seed=0)
    again = pol.act(obs)
    for k in act:
        np.testing.assert_array_equal(act[k], again[k])


def test_policy_falls_back_when_the_solver_fails(monkeypatch):
    env = parallel_env(topology="BDL")
    pol = DMPC(env, seed=0)
    obs, _ = env.reset(seed=0)
    monkeypatch.setattr(QPSolver, "solve_raw", lambda self: (np.full(self.n, np.nan), False, "x"))
    act = pol.act(obs)
    assert pol.info["fallbacks"] > 0
    assert all(np.all(np.isfinite(a)) and np.all(np.abs(a) <= 1) for a in act.values())
    env.step(act)  # the env accepts the fallback action


def test_policy_rejects_bad_options():
    env = parallel_env()
    with pytest.raises(BaselineError, match=r"DMPC: unknown option\(s\) \['horizont'\]"):
        DMPC(env, horizont=3)
    with pytest.raises(ValueError, match="variant"):
        DMPC(env, variant="central")
    with pytest.raises(BaselineTypeError, match="satenv env"):
        DMPC(object())
    with pytest.raises(ValueError, match="solver"):
        DMPC(env, solver="cplex")
    with pytest.raises(ValueError, match="warm_start"):
        DMPC(env, warm_start="cold")


def test_the_dmpc_follows_the_env_topology_override():
    env = parallel_env(topology=[[0, 0, 0, 0], [1, 0, 0, 0], [1, 0, 0, 0], [1, 0, 0, 0]])
    pol = DMPC(env)
    np.testing.assert_array_equal(pol.core.topology.adjacency, env.topology.adjacency)


# ---------------------------------------------------------------- pereira2022 convex step
P22 = PRESETS["pereira2022"]
C22 = DMPCConfig.paper("pereira2022")


def test_convex_step_unconstrained_converges_to_the_cooperative_optimum():
    """Many convex-step iterations (box inactive) -> the minimiser of the joint cost (eq. 25-28)."""
    sc = P22.with_overrides(u_max=1e6)
    ctl = ConvexStepDMPC(sc, constrained=False, iterations=3000)
    x = sc.initial_array()
    ctl.solve(x)
    # independent joint least squares: V = atot sum_i a_i |Z_i - Yd|_Q^2 + sum_j a_j^2 |U_j|_W^2
    a, b = cw_matrices(sc.mean_motion, sc.dt)
    ca, cb = prediction_matrices(a, b, C22.horizon)
    q = np.tile(np.asarray(sc.state_weight), C22.horizon)
    q[-6:] = C22.terminal_weight
    w = np.tile(np.asarray(sc.input_weight), C22.horizon)
    alpha = np.asarray(sc.alpha)
    m, nu = sc.n_followers, 3 * C22.horizon
    z = pair_states(sc, x)
    yd = np.tile(np.asarray(sc.desired_error), C22.horizon)
    rows, rhs, wts = [], [], []
    for i in range(m):  # Z_i = ca z_i + cb U_i - cb U_{i-1}
        g = np.zeros((6 * C22.horizon, m * nu))
        g[:, i * nu:(i + 1) * nu] = cb
        if i >= 1:
            g[:, (i - 1) * nu:i * nu] = -cb
        rows.append(g)
        rhs.append(yd - ca @ z[i])
        wts.append(alpha.sum() * alpha[i] * q)
    for j in range(m):
        g = np.zeros((nu, m * nu))
        g[:, j * nu:(j + 1) * nu] = np.eye(nu)
        rows.append(g)
        rhs.append(np.zeros(nu))
        wts.append(alpha[j] ** 2 * w)
    gm, r, wv = np.vstack(rows), np.concatenate(rhs), np.concatenate(wts)
    uopt = np.linalg.solve(gm.T @ (wv[:, None] * gm), gm.T @ (wv * r))
    np.testing.assert_allclose(ctl.U.ravel(), uopt, atol=1e-6 * np.abs(uopt).max())


def test_convex_step_keeps_los_and_keepout_on_the_2022_scenario():
    sc = P22
    ctl = ConvexStepDMPC(sc)
    a, b = cw_matrices(sc.mean_motion, sc.dt)
    x = sc.initial_array()
    for _ in range(120):
        x = x @ a.T + ctl.solve(x) @ b.T
        assert np.all(los_keepout_ok(sc, x))
    assert ctl.info["fallbacks"] == 0
    # close to the chain spacing y_d after 12 s
    assert np.abs(pair_states(sc, x)[:, :3] - [0, -10, 0]).max() < 0.5


def test_convex_step_policy_in_env():
    env = parallel_env(preset="pereira2022", max_steps=20)
    pol = DMPC(env)
    assert pol.variant == "convex_step"
    obs, _ = env.reset(seed=0)
    pol.reset(seed=0)
    while env.agents:
        obs, *_ = env.step(pol.act(obs))
    assert pol.info["fallbacks"] == 0 and len(pol.info["solve_ms"]) == 20
    assert pol.cfg == DMPCConfig.paper("pereira2022")


def test_convex_step_rejects_bad_weights():
    with pytest.raises(ValueError, match="sum"):
        ConvexStepDMPC(P22, convex_weights=[0.5, 0.6])
    with pytest.raises(ValueError, match="iterations"):
        ConvexStepDMPC(P22, iterations=0)


def test_custom_topology_object_is_accepted():
    topo = make_topology("TPLF", 4)
    ctl = OneHopDMPC(P23, topology=topo, seed=0)
    assert ctl.topology is topo
    assert ctl.solve(P23.initial_array()).shape == (4, 3)


def test_dmpc_reaches_the_chain_formation_without_collision():
    """The 1-hop DMPC targets (L_bar x*)_f, so it serves the collision-free chain formation too."""
    from satenv import metrics
    from satenv.baselines.dmpc import DMPC
    from satenv.envs.platoon_v0 import parallel_env
    from satenv.rollout import rollout

    env = parallel_env(formation="chain", terminate_on_collision=True)
    traj = rollout(env, DMPC(env), seed=0)
    assert traj.steps == env.scenario.max_steps and metrics.collisions(traj) == 0
    np.testing.assert_allclose(traj.states[-1, :, 1], [-8.0, -16.0, -24.0, -32.0], atol=1e-3)


def test_per_agent_stopping_is_algorithm_1():
    """Algorithm 1 line 15: each agent stops on its own. In PLF follower 1 hears only the leader,
    so from a random start it stops after 2 iterations however long the others iterate; with
    stopping="all" it keeps solving (the same QP) until the worst agent converges."""
    sc = P23.with_overrides(topology="PLF")
    x = sc.initial_array()
    solved = {}
    for stopping in ("per_agent", "all"):
        ctl = OneHopDMPC(sc, stopping=stopping, sigma=1e-6, seed=3)
        calls = []
        orig = ctl._local_constrained
        ctl._local_constrained = lambda *a, calls=calls, orig=orig: (calls.append(a[-1].copy()), orig(*a))[1]
        ctl.solve(x)
        solved[stopping] = np.sum(calls, axis=0)
    assert solved["per_agent"][0] == 2 and solved["all"][0] == solved["all"].max() > 2
    assert solved["per_agent"].max() == solved["all"].max()
    with pytest.raises(BaselineError, match="stopping"):
        DMPCConfig(stopping="worst")
    with pytest.raises(BaselineError, match="velocity_margin"):
        DMPCConfig(velocity_margin=-1.0)
