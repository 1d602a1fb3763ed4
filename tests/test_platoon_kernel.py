"""The compiled platoon kernel (issue 17) against the numpy reference paths it replaces."""

from __future__ import annotations

import numpy as np
import pytest

import satenv
from satenv.envs.platoon_v0 import PlatoonCore
from satenv.scenarios.platoon import resolve_scenario

pytest.importorskip("numba")


def _cores(n, topology="PLF", slots=False, batch=4, **overrides):
    rng = np.random.default_rng(n)
    sc = resolve_scenario("pereira2023", topology=topology, neighbour_slots=slots,
                          initial_state=rng.uniform(-60, 60, (n, 6)), **overrides)
    return [PlatoonCore(sc, batch=batch, method=m) for m in ("kernel", "dense", "sparse")]


def _assert_same(kernel, ref):
    for key in ref.info:
        np.testing.assert_allclose(kernel.info[key], ref.info[key], rtol=1e-12, atol=1e-12, err_msg=key)
        assert kernel.info[key].dtype == ref.info[key].dtype, key
    np.testing.assert_allclose(kernel.rewards, ref.rewards, rtol=1e-12)
    np.testing.assert_array_equal(kernel.terminated, ref.terminated)


CASES = [(topology, slots, n) for topology in ("PLF", "BDL", "TPLF", "RING") for slots in (False, True)
         for n in (1, 4, 9, 40) if topology != "RING" or n >= 3]   # a ring needs 3 followers


@pytest.mark.parametrize(("topology", "slots", "n"), CASES)
def test_kernel_matches_the_numpy_paths(topology, slots, n):
    cores = _cores(n, topology, slots, max_distance=200.0)
    assert cores[0].method == "kernel" and cores[1].dense and cores[2].method == "sparse"
    rng = np.random.default_rng(7)
    x = rng.uniform(-40, 40, (4, n, 6))
    x[..., 3:] *= 0.5
    x[1, 0, 3] = 100.0                             # a velocity-bound violation
    x[2, -1] = x[2, 0] + [1.0, 0, 0, 0, 0, 0]      # a collision (or the leader when n = 1)
    x[3, 0, :3] = [250.0, 0.0, 0.0]                # beyond max_distance
    infos = [c.reset(x) for c in cores]
    for info in infos[1:]:
        for key in info:
            np.testing.assert_allclose(infos[0][key], info[key], rtol=1e-12, atol=1e-12, err_msg=key)
    for step in range(3):
        accel = rng.uniform(-1, 1, (4, n, 3)) * (0.0 if step == 0 else 6.0)
        res = [c.step(accel) for c in cores]
        obs = [c.observe() for c in cores]
        for ref, ref_obs in zip(res[1:], obs[1:], strict=True):
            _assert_same(res[0], ref)
            np.testing.assert_allclose(obs[0], ref_obs, rtol=1e-6, atol=1e-6)
            assert obs[0].dtype == np.float32 and obs[0].shape == ref_obs.shape
        # the kernel's E and observation follow the sparse formulas: the same bits on the same
        # states (the compiled CW step agrees with the numpy one to rounding only)
        cores[2].x = res[0].info["state"].copy()
        np.testing.assert_array_equal(res[0].info["neighbourhood_error"],
                                      cores[2]._evaluate(cores[2].x, accel)[0]["neighbourhood_error"])
        np.testing.assert_array_equal(obs[0], cores[2].observe())
    assert res[0].terminated[3] and res[0].info["violations"][1, 0] >= 1
    if n > 1:
        assert res[0].info["collision"][2].any()


@pytest.mark.parametrize("batch", [1, 5])
def test_compiled_cw_step_matches_the_model(batch):
    """The kernel path's fused CW step (states and chief) against ``RelativeModel.step``."""
    kernel = _cores(4, batch=batch)[0]
    rng = np.random.default_rng(batch)
    x = rng.uniform(-50, 50, (batch, 4, 6))
    kernel.reset(x)
    chief = kernel.chief.copy()
    accel = rng.uniform(-6, 6, (batch, 4, 3))
    kernel.step(accel)
    x_ref, chief_ref = kernel.model.step(x, accel, chief)
    np.testing.assert_allclose(kernel.x, x_ref, rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(kernel.chief, chief_ref, rtol=1e-14, atol=1e-6)
    j2 = PlatoonCore(resolve_scenario("pereira2023", dynamics="j2"), method="kernel")
    assert kernel._cw_step is not None and j2._cw_step is None     # nonlinear models: numpy
    assert _cores(4, batch=64)[0]._cw_step is None                  # large batches: BLAS


def test_kernel_flags_the_copies_that_are_not_finite():
    """The step guard fused into the kernel: ``StepResult.finite`` per copy, no false alarm on
    huge finite values, and the float32 observation's overflow counts."""
    kernel = _cores(4, batch=4)[0]
    x = np.random.default_rng(1).uniform(-30, 30, (4, 4, 6))
    x[1, 2, 4] = np.nan
    x[2, 0, 0] = 1e300                  # a finite state whose observation overflows float32
    x[3, 3, 0] = 1e30                   # huge but finite everywhere (observation, reward)
    kernel.reset(x)
    res, obs = kernel.step_observe(np.zeros((4, 4, 3)))
    expected = [np.isfinite(obs[b]).all() and np.isfinite(res.rewards[b]).all()
                and np.isfinite(res.info["state"][b]).all() for b in range(4)]
    assert res.finite.tolist() == expected == [True, False, False, True]
    kernel.fused_check = False          # the env's StepGuard checks instead (satenv.bench.perf's A/B)
    assert kernel.step_observe(np.zeros((4, 4, 3)))[0].finite is None
    with pytest.raises(ValueError, match="kernel"):
        _cores(4)[1].fused_check = True


def test_kernel_partial_reset_and_fresh_arrays():
    kernel, dense, _ = _cores(4, batch=3)
    x = np.random.default_rng(0).uniform(-30, 30, (3, 4, 6))
    for c in (kernel, dense):
        c.reset(x)
    accel = np.full((3, 4, 3), 0.5)
    first = kernel.step(accel)
    kept = {k: v.copy() for k, v in first.info.items()}
    obs1 = kernel.observe()
    dense.step(accel)
    idx = np.array([1])
    part = [c.reset(x[idx] * 0.5, idx) for c in (kernel, dense)]
    for key in part[1]:
        np.testing.assert_allclose(part[0][key], part[1][key], rtol=1e-12, atol=1e-12, err_msg=key)
    np.testing.assert_allclose(kernel.observe(), dense.observe(), rtol=1e-6, atol=1e-6)
    for key, value in first.info.items():   # the core never writes into arrays it returned
        np.testing.assert_array_equal(value, kept[key], err_msg=key)
    assert kernel.observe() is not kernel.observe()
    assert not np.shares_memory(obs1, kernel.observe())


def test_kernel_selection():
    env = satenv.make("platoon_v0")
    assert env.core.method == "kernel" and not env.core.dense
    constrained = satenv.make("platoon_v0", preset="pereira2022")   # optional constraints: numpy
    assert constrained.core.method == "dense"
    with pytest.raises(ValueError, match="optional constraints"):
        PlatoonCore(constrained.scenario, method="kernel")
    with pytest.raises(ValueError, match="method must be one of"):
        PlatoonCore(env.scenario, method="fast")


def test_pettingzoo_episode_matches_the_reference():
    """A whole seeded episode of the env, kernel against the dense reference core."""
    envs = [satenv.make("platoon_v0", randomize=True, max_steps=40) for _ in range(2)]
    envs[1].core = PlatoonCore(envs[1].scenario, batch=1, method="dense")
    outs = [env.reset(seed=3) for env in envs]
    rng = np.random.default_rng(0)
    while envs[0].agents:
        acts = {a: rng.uniform(-1, 1, 3).astype(np.float32) for a in envs[0].agents}
        outs = [env.step(acts) for env in envs]
        (o0, r0, t0, u0, i0), (o1, r1, t1, u1, i1) = outs
        assert t0 == t1 and u0 == u1
        for a in o0:
            np.testing.assert_allclose(o0[a], o1[a], rtol=1e-6, atol=1e-6)
            assert r0[a] == pytest.approx(r1[a], rel=1e-12)
            for key in i1[a]:
                np.testing.assert_allclose(i0[a][key], i1[a][key], rtol=1e-12, atol=1e-12, err_msg=key)
        # the physics: the compiled CW step against the model's numpy products, to rounding
        np.testing.assert_allclose(envs[0].state(), envs[1].state(), rtol=1e-13, atol=1e-12)


def test_pettingzoo_dicts_are_fresh_and_infos_safe_to_keep():
    """The PettingZoo contract the fast step keeps: new dicts every step, and what a step handed
    out (observations, infos) never changes afterwards (later steps, resets)."""
    env = satenv.make("platoon_v0", max_steps=3)
    obs0, infos0 = env.reset(seed=0)
    kept_obs0 = {a: v.copy() for a, v in obs0.items()}
    acts = {a: np.full(3, 0.5, np.float32) for a in env.agents}
    first = env.step(acts)
    kept = {a: {k: np.copy(v) for k, v in info.items()} for a, info in first[4].items()}
    second = env.step(acts)
    assert all(d1 is not d2 for d1, d2 in zip(first, second, strict=True))
    for a in env.possible_agents:
        assert first[4][a] is not second[4][a] and first[4][a] is not infos0[a]
        assert not np.shares_memory(first[4][a]["state"], second[4][a]["state"])
        assert not np.shares_memory(first[0][a], second[0][a])
    env.step(acts)
    env.reset(seed=1)
    for a, info in first[4].items():
        for key, value in info.items():
            np.testing.assert_array_equal(value, kept[a][key], err_msg=key)
    for a, value in obs0.items():
        np.testing.assert_array_equal(value, kept_obs0[a])


@pytest.mark.parametrize(("topology", "slots", "n"), [("PLF", False, 4), ("RING", True, 9)])
def test_step_observe_is_step_then_observe(topology, slots, n):
    fused, plain = _cores(n, topology, slots)[0], _cores(n, topology, slots)[0]
    x = np.random.default_rng(1).uniform(-40, 40, (4, n, 6))
    for core in (fused, plain):
        core.reset(x)
    for k in range(3):
        accel = np.full((4, n, 3), 0.1 * k)
        res, obs = fused.step_observe(accel)
        ref = plain.step(accel)
        np.testing.assert_array_equal(obs, plain.observe())
        np.testing.assert_array_equal(res.rewards, ref.rewards)
        for key in ref.info:
            np.testing.assert_array_equal(res.info[key], ref.info[key], err_msg=key)


def _squared(d):
    return d[0] * d[0] + d[1] * d[1] + d[2] * d[2]   # the kernel's formula, in the same order


@pytest.mark.parametrize("layout", ["random", "line", "lattice", "clusters"])
def test_sweep_nearest_distances_equal_all_pairs_bitwise(layout):
    """The kernel's sort-and-sweep search (above ``SWEEP_MIN`` followers) against all pairs,
    including ties (a lattice), every follower on one line (no pruning along the sort axis) and
    duplicates."""
    from satenv.envs._platoon_kernel import SWEEP_MIN, _nearest_sq

    rng = np.random.default_rng(3)
    n = 3 * SWEEP_MIN
    x = np.zeros((2, n, 6))
    if layout == "random":
        x[..., :3] = rng.uniform(-500, 500, (2, n, 3))
    elif layout == "line":
        x[..., 1] = rng.uniform(-500, 500, (2, n))
    elif layout == "lattice":
        x[..., :3] = np.stack(np.meshgrid(*[np.arange(6.0)] * 3, indexing="ij"), -1).reshape(-1, 3)[:n] * 10
    else:
        x[..., :3] = rng.integers(0, 4, (2, n, 3)) * 100.0 + rng.normal(size=(2, n, 3))
        x[0, 5, :3] = x[0, 7, :3]            # a duplicate: distance 0
    pos = x[..., :3]
    diff = pos[:, :, None] - pos[:, None]
    d2 = (diff * diff).sum(-1)
    d2[:, np.arange(n), np.arange(n)] = np.inf
    out = np.empty(n)
    for b in range(2):
        _nearest_sq(x, b, out)
        ref = np.array([min(_squared(pos[b, f] - pos[b, j]) for j in range(n) if j != f) for f in range(n)])
        np.testing.assert_array_equal(out, ref)
        np.testing.assert_allclose(out, d2[b].min(-1), rtol=1e-15)


def test_kernel_is_the_default_for_swarms():
    from satenv.scenarios.platoon import swarm

    sc = resolve_scenario(**{k: v for k, v in swarm(100, "ring", "RING").items() if k != "preset"})
    assert PlatoonCore(sc, batch=2).method == "kernel"
