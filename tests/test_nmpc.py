"""satenv.baselines.nmpc: the cooperative NMPC of pereira2022 §4 on satenv.servicing_v0."""

import numpy as np
import pytest

pytest.importorskip("casadi")

from satenv.baselines.nmpc import NMPC, attitude_reference_sym, build_model, quaternion_cost_terms  # noqa: E402
from satenv.dynamics import cw_continuous  # noqa: E402
from satenv.dynamics.attitude import attitude_derivative, quat_error, thruster_matrices  # noqa: E402
from satenv.envs.servicing_v0 import attitude_reference, parallel_env  # noqa: E402
from satenv.rollout import rollout  # noqa: E402
from satenv.scenarios.servicing import PRESETS  # noqa: E402


def random_states(rng, n):
    x = np.zeros((n, 13))
    x[:, :3] = rng.normal(size=(n, 3)) * 20
    x[:, 3:6] = rng.normal(size=(n, 3))
    q = rng.normal(size=(n, 4))
    x[:, 6:10] = q / np.linalg.norm(q, axis=1, keepdims=True)
    x[:, 10:] = rng.normal(size=(n, 3)) * 0.5
    return x


@pytest.mark.parametrize(("frame", "radius", "att_tol"),
                         [("lvlh", 6621e3, 1e-5), ("body", 6621e3, 1e-5), ("lvlh", 1e9, 1e-11)])
def test_casadi_model_matches_numpy_physics(frame, radius, att_tol):
    """The NMPC's eq. 35 (CasADi) equals satenv.dynamics (CW translation, attitude module).

    The discrete model holds the orbital-rate coupling of eq. 14-15 (~ J n |omega|) over each
    step: a ~1e-6 rad/s difference per step at |omega| ~ 1 rad/s in LEO, which vanishes with n.
    """
    sc = PRESETS["pereira2022"].with_overrides(thrust_frame=frame, orbit_radius=radius)
    f, F = build_model(sc)
    env = parallel_env(thrust_frame=frame, dynamics="cw", terminate_on_collision=False,
                       max_distance=1e6, orbit_radius=radius)
    rng = np.random.default_rng(0)
    a_c, _ = cw_continuous(sc.mean_motion)
    f_t, f_r = thruster_matrices(sc.dimensions)
    j_f, j_l = np.array(sc.inertia), np.array(sc.object_inertia)
    w_l = np.array([0, 0, sc.mean_motion])
    from satenv.dynamics.attitude import quat_to_matrix

    for x in random_states(rng, 5):
        u = rng.uniform(-3, 3, 6)
        xdot = np.asarray(f(x, u)).ravel()
        force = f_t @ u if frame == "lvlh" else quat_to_matrix(x[6:10]) @ (f_t @ u)
        np.testing.assert_allclose(xdot[:6], a_c @ x[:6] + np.r_[0, 0, 0, force], atol=1e-12)
        np.testing.assert_allclose(xdot[6:], attitude_derivative(x[6:], f_r @ u, j_f, j_l, w_l), atol=1e-12)
        # one discrete step against the env's truth step (CW translation, RK4 attitude)
        env.reset(options={"initial_state": np.stack([x, x])})
        _, _, _, _, info = env.step({a: u / 3.0 for a in env.agents})
        nxt = np.asarray(F(x, u)).ravel()
        np.testing.assert_allclose(nxt[:6], info["sat_1"]["state"][:6], atol=1e-10)
        np.testing.assert_allclose(nxt[6:], info["sat_1"]["state"][6:], atol=att_tol)


def test_nmpc_keeps_every_constraint_on_the_paper_start():
    """First 3.5 s of §5.2: keep-out, velocity and input bounds become active, omega nearly."""
    env = parallel_env(max_steps=35)
    policy = NMPC(env)
    traj = rollout(env, policy, seed=0)
    sc = env.scenario
    info = traj.info
    assert traj.steps == 35 and not traj.terminated
    assert info["violations"].sum() == 0 and not info["collision"].any()
    assert policy.info["fallbacks"] == 0
    assert info["dist_object"].min() >= sc.keepout_radius - sc.contact_tolerance
    assert np.abs(traj.states[..., 3:6]).max() <= sc.v_max
    assert np.abs(traj.states[..., 10:]).max() <= sc.omega_max
    assert np.abs(info["thrust"]).max() <= 3.0 + 1e-9
    # the constraints are exercised, not idle: the run presses against the limits
    assert np.abs(traj.states[..., 3:6]).max() > 0.95 * sc.v_max
    assert np.abs(info["thrust"]).max() > 0.99 * 3.0
    assert np.abs(traj.states[..., 10:]).max() > 0.8 * sc.omega_max
    assert info["dist_object"][1:].min() < sc.keepout_radius + 0.01
    # and it makes progress around the object towards the first waypoints (30 m away)
    err = np.linalg.norm(info["tracking_error"][-1], axis=-1)
    assert np.all(err < 25.0)
    assert len(policy.info["agent_solve_ms"]) == 70 and len(policy.info["solve_ms"]) == 35


def test_coupled_collision_constraint_when_paths_cross():
    """Two spacecraft swap places: the sequential NMPC keeps r_i + r_j = 6 m between them."""
    p0 = [[-10.0, 25.0, 0.0], [10.0, 25.0, 0.5]]
    goal = [[10.0, 25.0, 0.0], [-10.0, 25.0, 0.5]]
    env = parallel_env(initial_position=p0, initial_velocity=[[0, 0, 0]] * 2, waypoints=[goal],
                       waypoint_times=[], max_steps=80)
    policy = NMPC(env)
    traj = rollout(env, policy, seed=0)
    info = traj.info
    assert not traj.terminated and info["violations"].sum() == 0
    assert info["dist_other"].min() >= env.scenario.separation_radius
    assert info["dist_other"].min() < env.scenario.separation_radius + 0.1   # constraint active
    assert np.all(np.linalg.norm(info["tracking_error"][-1], axis=-1) < 0.5)


def test_failed_solves_fall_back_to_a_flagged_safe_action():
    env = parallel_env(max_steps=3)
    policy = NMPC(env, max_iter=1)        # ipopt stops at its iteration limit: not a success
    obs, _ = env.reset(seed=0)
    policy.reset()
    act = policy.act(obs)
    assert policy.info["fallbacks"] == 2
    assert all(status.startswith("Maximum_Iterations") for status in policy.info["statuses"])
    for a in act.values():
        assert a.shape == (6,) and np.all(np.isfinite(a)) and np.all(np.abs(a) <= 1.0)
    # the brake-and-hold action pushes a spacecraft that is inside the keep-out margin outwards
    x = env.state()[:13].copy()
    u = policy.safe_action(x)
    f_t, _ = thruster_matrices(env.scenario.dimensions)
    assert np.all(np.abs(u) <= 3.0 + 1e-12)
    assert (f_t @ u) @ x[:3] > 0


def test_bad_options_rejected():
    env = parallel_env()
    with pytest.raises(ValueError, match="solver"):
        NMPC(env, solver="snopt")
    with pytest.raises(ValueError, match="order"):
        NMPC(env, order="random")
    with pytest.raises(ValueError, match="horizon"):
        NMPC(env, horizon=0)
    with pytest.raises(ValueError, match="unknown option"):
        NMPC(env, horizn=10)

    class Other:
        scenario = object()
        possible_agents = ["a"]
    with pytest.raises(TypeError, match="servicing"):
        NMPC(Other())


def test_attitude_reference_inside_the_nlp_matches_the_env():
    """Eq. 43-49 as CasADi expressions of (p, v, q) equal the env's reference (q_d up to sign),
    also next to the min_sine switch of the frame; the quaternion error ignores q_d's sign."""
    import casadi as ca

    sc = PRESETS["pereira2022"]
    p, v, q = ca.SX.sym("p", 3), ca.SX.sym("v", 3), ca.SX.sym("q", 4)
    q_d, w_d = attitude_reference_sym(sc, p, v, q)
    fun = ca.Function("ref", [p, v, q], [q_d, w_d, quaternion_cost_terms(q, q_d),
                                         quaternion_cost_terms(q, -q_d)])
    rng = np.random.default_rng(1)
    ref = np.asarray(sc.pointing_reference)
    for k, x in enumerate(random_states(rng, 300)):
        pos = -15 * ref + rng.normal(size=3) * 0.5 if k % 10 == 0 else x[:3]
        qd_s, wd_s, e_s, e_neg = (np.asarray(a).ravel() for a in fun(pos, x[3:6], x[6:10]))
        _, qd_n, wd_n = attitude_reference(sc, pos, x[3:6], x[6:10])
        assert min(np.abs(qd_s - qd_n).max(), np.abs(qd_s + qd_n).max()) < 1e-12
        np.testing.assert_allclose(wd_s, wd_n, atol=1e-12)
        err = quat_error(x[6:10], qd_n)
        np.testing.assert_allclose(e_s[0], 1 - err[0], atol=1e-12)
        np.testing.assert_allclose(np.abs(e_s[1:]), np.abs(err[1:]), atol=1e-12)
        np.testing.assert_allclose(np.abs(e_neg), np.abs(e_s), atol=1e-12)


@pytest.mark.slow
def test_full_pereira2022_run_meets_the_three_claims_per_phase():
    """The whole §5.2 episode (120 s, about 1.5 min): constraints, waypoints, and the pointing error
    <= 5 deg at the end of every phase of every spacecraft and over its last 10 s."""
    from satenv.bench.reproductions.pereira2022_servicing import POINTING_TOL_DEG, analyse

    env = parallel_env()
    policy = NMPC(env)
    traj = rollout(env, policy, seed=0)
    result = analyse(traj, env, policy)
    assert policy.info["fallbacks"] == 0
    for row in result["rows"]:
        assert row["final_position_error_m"] < 0.01
        for phase in row["phases"]:
            assert phase["pointing_at_phase_end_deg"] <= POINTING_TOL_DEG, (row["agent"], phase)
            assert phase["pointing_max_last_10s_deg"] <= POINTING_TOL_DEG, (row["agent"], phase)
    assert result["constraints_ok"]
