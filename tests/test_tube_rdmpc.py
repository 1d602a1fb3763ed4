"""satenv.baselines.TubeRDMPC (li2022 §3): tube bound (15), collision avoidance, fallbacks, options."""

import math

import numpy as np
import pytest

pytest.importorskip("casadi")

from satenv import metrics  # noqa: E402
from satenv.baselines.tube_rdmpc import TubeController, TubeRDMPC, TubeRDMPCConfig, slot_sizes  # noqa: E402
from satenv.envs.cluster_v0 import parallel_env  # noqa: E402
from satenv.rollout import rollout  # noqa: E402

SHORT_STEPS = 36   # 180 s of the li2022 scenarios in the default suite (the full run is in benchmarks)


def tube_only_run(k1: float, enabled: bool = True, steps: int = 64) -> np.ndarray:
    """Coasting nominal (zero commanded input) + the tube controller κ on the J2 + drag + w truth.

    Returns ``||q - q~||`` at every physics step (T, M). 64 decisions = 320 s, one period of the
    li2022 sinusoid (2 pi / 0.02 = 314 s).
    """
    env = parallel_env(terminate_on_collision=False, max_steps=steps)
    env.reset(seed=0)
    sc = env.scenario
    tube = TubeController(sc.orbit.n, sc.physics_dt, k1=k1, k2=4.0)
    tube.enabled = enabled
    tube.sync(env.state()[:60].reshape(10, 6), 0.0)
    env.set_inner_loop(tube)
    for _ in range(steps):
        env.step({a: np.zeros(3) for a in env.agents})
    return np.array(tube.eps)


def test_tube_bound_15_holds_and_shrinks_with_k1():
    sc = parallel_env().scenario
    w_bar = sc.disturbance_bound + 5e-5             # sup ||w|| + the CW model-error bound
    maxima = {}
    for k1 in (1.0, 2.0, 4.0):
        eps = tube_only_run(k1)
        maxima[k1] = eps.max()
        bound_15 = math.sqrt(1.0 / k1) * w_bar        # eq. (15) with eta = 1
        exact = w_bar / (1.0 + k1)                    # peak gain of eps'' + (k1+k2) eps' + (1+k1) eps = w
        assert maxima[k1] <= bound_15
        assert maxima[k1] <= exact * 1.01
        assert maxima[k1] >= 0.5 * exact             # the disturbance really drives the tube
    assert maxima[1.0] > maxima[2.0] > maxima[4.0]    # li2022 Fig. 13: larger k1, smaller error
    # without kappa the same disturbance drives the true state far from the nominal
    assert tube_only_run(2.0, enabled=False, steps=10).max() > 100 * maxima[2.0]


def test_nominal_propagation_matches_the_dmpc_prediction():
    env = parallel_env(max_steps=3)
    pol = TubeRDMPC(env)
    rollout(env, pol, seed=0, max_steps=1)
    # the nominal the tube controller propagated at the physics rate equals the plan's x~(t_1)
    np.testing.assert_allclose(pol.tube.nominal, pol.plans[:, 1], rtol=0, atol=1e-7)


@pytest.mark.parametrize("preset", ["li2022-case1", "li2022-case2"])
def test_short_run_is_collision_free_within_thrust_and_tube(preset):
    env = parallel_env(preset=preset, terminate_on_collision=False)
    pol = TubeRDMPC(env)
    traj = rollout(env, pol, seed=0, max_steps=SHORT_STEPS)
    sc = env.scenario
    assert metrics.collisions(traj) == 0
    assert traj.info["pair_distance"].min() >= sc.pair_distance
    assert traj.info["obstacle_distance"].min() >= sc.obstacle_distance
    assert np.max(traj.info["thrust_peak"]) <= sc.u_max * (1 + 1e-9)
    assert pol.info["fallbacks"] == 0
    assert pol.info["tube_error_max_m"] <= pol.info["tube_bound_m"]
    assert len(pol.info["solve_ms"]) >= SHORT_STEPS * 10
    err = np.linalg.norm(traj.info["tracking_error"][..., :3], axis=-1)
    assert np.all(err[-1] < err[0] - 100.0)           # every satellite is on its way


def test_single_satellite_avoids_the_moving_obstacle():
    # straight line to the target runs through the obstacle's 400 m keep-out
    env = parallel_env(initial_positions=[[1300.0, 0.0, 0.0]], targets=[[-400.0, 0.0, 0.0]],
                       terminate_on_collision=False, max_steps=80)
    pol = TubeRDMPC(env)
    traj = rollout(env, pol, seed=0)
    assert traj.info["obstacle_distance"].min() >= env.scenario.obstacle_distance
    assert metrics.collisions(traj) == 0 and pol.info["fallbacks"] == 0
    assert np.linalg.norm(traj.info["tracking_error"][-1, 0, :3]) < 1200.0   # 500 m of progress


def test_two_satellites_swapping_places_keep_their_distance():
    env = parallel_env(initial_positions=[[-700.0, 600.0, 300.0], [-700.0, 1400.0, 300.0]],
                       targets=[[-700.0, 1400.0, 200.0], [-700.0, 600.0, 200.0]], allocation="fixed",
                       disturbance="none", terminate_on_collision=False, max_steps=50)
    pol = TubeRDMPC(env)
    traj = rollout(env, pol, seed=0)
    assert traj.info["pair_distance"].min() >= env.scenario.pair_distance
    assert metrics.collisions(traj) == 0


def test_solver_failure_degrades_to_flagged_fallback(monkeypatch):
    env = parallel_env(max_steps=4)
    pol = TubeRDMPC(env)
    rollout(env, pol, seed=0, max_steps=2)                       # a valid plan exists
    def fail(**_):
        raise RuntimeError("forced failure")

    monkeypatch.setattr(pol.nlp, "solver_for", lambda k, copy=0, relaxed=False: fail)
    obs, _ = env.reset(seed=0)
    pol.reset()
    for _ in range(2):
        actions = pol.act(obs)
        assert all(np.all(np.isfinite(a)) and np.linalg.norm(a) <= 1.0 for a in actions.values())
        obs, *_ = env.step(actions)
    assert pol.info["fallbacks"] == 2 * 10 and pol.info["relaxed"] == 2 * 10
    assert pol.info["solver_status"] == "error: RuntimeError: forced failure"


def test_worker_threads_give_the_same_decisions_as_one():
    """``workers=2`` solves the satellites' independent NLPs on two threads with two solver copies:
    the same actions, statuses and counts as in turn."""
    runs = []
    for workers in (1, 2):
        env = parallel_env(max_steps=3)
        pol = TubeRDMPC(env, horizon=15.0, workers=workers)
        obs, _ = env.reset(seed=3)
        pol.reset(seed=3)
        acts = []
        for _ in range(3):
            act = pol.act(obs)
            acts.append(np.stack([act[a] for a in env.possible_agents]))
            obs, *_ = env.step(act)
        runs.append((np.stack(acts), pol.info["solves"], pol.info["relaxed"], pol.history["status"]))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    assert runs[0][1:] == runs[1][1:]
    with pytest.raises(ValueError, match="workers"):
        TubeRDMPC(parallel_env(), workers=0)


def test_exact_max_iter_caps_the_exact_nlp_only():
    """``exact_max_iter`` limits the exact NLP's ipopt iterations; the relaxed NLP that follows a
    failure keeps ``max_iter`` (its own solver)."""
    env = parallel_env(max_steps=3)
    default = TubeRDMPC(env, horizon=15.0)
    assert default.nlp.solver_for(9, relaxed=True) is default.nlp.solver_for(9)
    capped = TubeRDMPC(env, horizon=15.0, exact_max_iter=1)     # too few for any exact solve
    assert capped.nlp.solver_for(9, relaxed=True) is not capped.nlp.solver_for(9)
    obs, _ = env.reset(seed=0)
    capped.reset(seed=0)
    capped.act(obs)
    assert capped.info["relaxed"] == 10 and capped.info["fallbacks"] == 0
    assert capped.info["solver_status"] == "Solve_Succeeded"   # the relaxed solves succeeded
    with pytest.raises(ValueError, match="exact_max_iter"):
        TubeRDMPC(env, exact_max_iter=0)


def test_neighbour_slots_follow_the_degree():
    """Each satellite's NLP has the smallest built slot count that holds its neighbours; the
    unused slots are inactive rows, so the optimum is that of the NLP with every slot."""
    assert slot_sizes(10, 4) == (5, 8, 9) and slot_sizes(64, 4) == (5, 8, 16, 63)
    assert slot_sizes(2, 4) == (1,) and slot_sizes(5, 0) == (1, 4)
    env = parallel_env(max_steps=3)
    pol = TubeRDMPC(env, horizon=15.0)
    problems = []
    solve = pol.nlp.solve

    def recording(info, params, w0, relaxed, duals=None, copy=0):
        problems.append((params.copy(), w0.copy(), relaxed))
        return solve(info, params, w0, relaxed, duals, copy)

    pol.nlp.solve = recording
    obs, _ = env.reset(seed=0)
    pol.reset(seed=0)
    for _ in range(2):
        obs, *_ = env.step(pol.act(obs))
    pol.nlp.solve = solve
    nlp, n = pol.nlp, pol.N
    assert {nlp.slots(p) for p, _, _ in problems} < set(nlp.slot_sizes)
    assert sum(nlp.slots(p) < nlp.K for p, _, _ in problems) >= 10
    for params, w0, relaxed in problems:
        k = nlp.slots(params)
        if k == nlp.K:
            continue
        head, tail = params[:9], params[9 + k * nlp._per_slot:]
        slots = params[9:9 + k * nlp._per_slot]
        qn, rest = slots[:3 * (n + 1) * k], slots[3 * (n + 1) * k:]
        pad = nlp.K - k                              # the same problem with every slot (far ones)
        full = np.concatenate([head, qn, np.full(3 * (n + 1) * pad, 1.0e5), rest[:3 * k], np.zeros(3 * pad),
                               rest[3 * k:], np.zeros(3 * pad), tail])
        w_k, w_full = nlp.solve({}, params, w0, relaxed), nlp.solve({}, full, w0, relaxed)
        assert (w_k is None) == (w_full is None)
        if w_k is not None:
            assert np.abs(w_k[:3] - w_full[:3]).max() <= 1e-6


def test_options_are_validated():
    env = parallel_env()
    with pytest.raises(ValueError, match="unknown option"):
        TubeRDMPC(env, horizon_s=50)
    with pytest.raises(ValueError, match="sigma"):
        TubeRDMPC(env, sigma=1.5)
    with pytest.raises(ValueError, match="k2 >= 1 / \\(4 eta\\)"):
        TubeRDMPC(env, k2=0.1, eta=0.5)
    with pytest.raises(ValueError, match="multiple of the decision period"):
        TubeRDMPC(env, horizon=52.0)
    with pytest.raises(TypeError, match="cluster_v0"):
        TubeRDMPC(object())
    with pytest.raises(ValueError, match=r"at most 200 decision periods"):
        TubeRDMPC(env, horizon=1e300)


def test_published_configuration_drops_our_two_additions():
    cfg = TubeRDMPCConfig.published()
    assert cfg.v_max is None and cfg.terminal_braking is False
    assert cfg.safety_margin == TubeRDMPCConfig().safety_margin
    assert TubeRDMPCConfig.published(sigma=0.3).sigma == 0.3
    with pytest.raises(ValueError, match="unknown option"):
        TubeRDMPCConfig.published(vmax=1.0)


# The li2022 reproduction's claims and full run: tests/test_reproduce_li2022.py
