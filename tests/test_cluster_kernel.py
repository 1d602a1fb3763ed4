"""The cluster core's fused step (compiled truth kernel + compiled separations, issue 25) against
its physics-step loop on the numpy truth model (the reference).

Tolerance 1e-10 relative (states, rewards, distances): the fused step integrates the same ODE,
with one DOP853 step per decision (the disturbance's staircase inside it exactly, the positions
at the physics steps interpolated: ``tests/test_dynamics_dop853.py``), or with the same RK4 steps
for the random disturbance (then it differs from the loop only in rounding: frame round trips
skipped, ``delta_v`` as one product instead of a sum of 20 equal terms, ~1e-15 relative per
decision). Integer and boolean outputs (violations, collisions, terminations) must be equal.
"""

from __future__ import annotations

import numpy as np
import pytest
from step_results import assert_same_step

from satenv.dynamics import RelativeModel
from satenv.envs.cluster_v0 import ClusterCore
from satenv.scenarios.cluster import resolve_scenario

pytest.importorskip("numba")

RTOL = 1e-10


def _pair(method="auto", batch=3, decisions=12, **overrides):
    sc = resolve_scenario("li2022-case1", **overrides)
    fused = ClusterCore(sc, batch=batch, method=method)
    ref = ClusterCore(sc, batch=batch, method=method, fused=False)
    ref.model = RelativeModel(sc.dynamics, sc.orbit, sc.physics_dt, method="numpy")
    assert fused._kernel is not None and fused.model._cache["kernel"] is not None
    return sc, fused, ref, decisions


def _run(sc, fused, ref, decisions, seed=0):
    rng = np.random.default_rng(seed)
    x0 = fused.sample_initial_state(rng, fused.batch)
    x0[..., :3] += rng.normal(size=x0[..., :3].shape) * 50.0
    g1, g2 = np.random.default_rng(5), np.random.default_rng(5)
    for core, g in ((fused, g1), (ref, g2)):
        core.reset(x0, None, g)
    for _ in range(decisions):
        a = rng.uniform(-1.5, 1.5, (fused.batch, fused.n_agents, 3)) * sc.u_max
        rf, rr = fused.step(a, g1), ref.step(a, g2)
        for key, val in rr.info.items():
            if val.dtype.kind in "biu":
                np.testing.assert_array_equal(rf.info[key], val, err_msg=key)
            else:
                np.testing.assert_allclose(rf.info[key], val, rtol=RTOL, atol=RTOL * 1e3, err_msg=key)
        np.testing.assert_allclose(rf.rewards, rr.rewards, rtol=RTOL)
        np.testing.assert_array_equal(rf.terminated, rr.terminated)
        np.testing.assert_allclose(fused.chief, ref.chief, rtol=RTOL, atol=0)
        np.testing.assert_allclose(fused.observe(), ref.observe(), rtol=1e-6, atol=1e-6)
        np.testing.assert_array_equal(fused.observe()[..., 19::7], ref.observe()[..., 19::7])  # slots
    assert g1.random() == g2.random()   # the same draws from the generator
    return rf.info


@pytest.mark.parametrize("disturbance", ["none", "sinusoid", "random"])
def test_fused_step_matches_the_loop(disturbance):
    _run(*_pair(disturbance=disturbance))


@pytest.mark.parametrize("method", ["dense", "sparse"])
def test_fused_step_matches_the_loop_on_both_separation_paths(method):
    # close satellites: the pair distances cross the 200 m safety distance in these episodes
    rng = np.random.default_rng(3)
    pos = rng.uniform(-250, 250, (10, 3))
    sc, fused, ref, n = _pair(method, initial_positions=pos, dynamics="nonlinear")
    info = _run(sc, fused, ref, n, seed=1)
    assert (info["pair_distance"] < sc.pair_distance).any()


def test_compiled_graph_and_observation_match_the_reference_bitwise():
    """Same states in both cores: the compiled observation and degrees equal the numpy ones, with
    satellites out of range and tied distances (a lattice) included."""
    grid = np.stack(np.meshgrid([0.0, 300.0], [0.0, 300.0, 600.0], [0.0, 2500.0], indexing="ij"), -1)
    pos = grid.reshape(-1, 3)[:10]
    for n_nb in (2, 4, 9):
        sc, fused, ref, _ = _pair(batch=4, initial_positions=pos, n_neighbours=n_nb)
        rng = np.random.default_rng(n_nb)
        x0 = np.zeros((4, 10, 6))
        x0[..., :3] = pos
        x0[1:, :, :3] += rng.normal(size=(3, 10, 3)) * 200.0
        x0[..., 3:] = rng.normal(size=(4, 10, 3))
        for core in (fused, ref):
            core.reset(x0)
            core.t[:] = [0, 5, 17, 399]
        np.testing.assert_array_equal(fused.observe(), ref.observe())
        np.testing.assert_array_equal(fused._degrees(fused.x[..., :3]), ref._degrees(ref.x[..., :3]))
        np.testing.assert_array_equal(fused.observe_copies(np.array([3, 1])), ref.observe()[[3, 1]])
        empty = (ref.observe()[..., 19::7] == 0).any()
    assert empty   # out-of-range satellites leave empty slots (n_neighbours = 9)


def test_inner_loop_takes_the_physics_step_loop():
    sc, fused, _, _ = _pair(batch=1)

    class Zero:
        calls = 0

        def correction(self, t, x, chief, u_cmd):
            Zero.calls += 1
            return np.zeros_like(u_cmd)

    fused.reset(fused.sample_initial_state(np.random.default_rng(0), 1))
    fused.inner_loop = Zero()
    fused.step(np.zeros((1, fused.n_agents, 3)))
    assert Zero.calls == sc.substeps


@pytest.mark.parametrize("overrides", [{}, {"disturbance": "random"}, {"reallocate_every": 3},
                                       {"terminate_on_collision": False}])
def test_one_pass_decision_matches_the_glue_bit_for_bit(overrides):
    """The dense step's one compiled pass (_cluster_kernel.decision: separations, infos, rewards,
    graph, observation) against the numpy glue around the separations kernel, through step,
    step_observe and resets of some copies (copies at different steps)."""
    sc = resolve_scenario("li2022-case1", **overrides)
    one, glue = ClusterCore(sc, batch=8), ClusterCore(sc, batch=8)
    glue._one_pass = False
    rng = np.random.default_rng(4)
    g1, g2 = np.random.default_rng(6), np.random.default_rng(6)
    x0 = one.sample_initial_state(rng, 8)
    for core, g in ((one, g1), (glue, g2)):
        core.reset(x0, None, g)
    for k in range(16):
        a = rng.uniform(-1.5, 1.5, (8, one.n_agents, 3)) * sc.u_max
        if k % 2:
            (r1, o1), (r2, o2) = one.step_observe(a, g1), glue.step_observe(a, g2)
            assert o1.dtype == o2.dtype
            np.testing.assert_array_equal(o1, o2)
            assert r1.finite.all()
        else:
            r1, r2 = one.step(a, g1), glue.step(a, g2)
        assert_same_step(r1, r2)
        np.testing.assert_array_equal(one.x, glue.x)
        np.testing.assert_array_equal(one.observe(), glue.observe())
        if k % 5 == 4 or r1.terminated.any():
            idx = np.union1d(np.flatnonzero(r1.terminated), [k % 8])
            x1 = one.sample_initial_state(rng, len(idx))
            for core, g in ((one, g1), (glue, g2)):
                core.reset(x1, idx, g)
