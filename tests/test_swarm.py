"""Swarms (issue 19): the neighbour-gather platoon path against the dense one, the exact
nearest-body kernels against each other, and the swarm generator."""

import numpy as np
import pytest

import satenv
from satenv.envs.platoon_v0 import PlatoonCore
from satenv.neighbours import nearest
from satenv.scenarios._fields import MAX_AGENTS
from satenv.scenarios.platoon import resolve_scenario, swarm


@pytest.mark.parametrize("m", [1, 2, 5, 40])
@pytest.mark.parametrize("k", [1, 3])
def test_nearest_tree_matches_dense(m, k):
    rng = np.random.default_rng(m + k)
    pos = rng.uniform(-100, 100, (3, m, 3))
    pos[1, -1] = pos[1, 0]  # coincident bodies
    d_dense, i_dense = nearest(pos, k, "dense")
    d_tree, i_tree = nearest(pos, k, "tree")
    np.testing.assert_array_equal(d_dense, d_tree)
    brute = np.linalg.norm(pos[:, :, None] - pos[:, None], axis=-1) + np.where(np.eye(m), np.inf, 0)
    np.testing.assert_allclose(d_dense[..., 0], brute.min(-1) if m > 1 else np.inf, rtol=1e-12)
    assert (i_dense[..., : m - 1] >= 0).all() and (i_tree[..., : m - 1] >= 0).all()


@pytest.mark.parametrize("topology", ["PLF", "BDL", "TPLF", "RING"])
@pytest.mark.parametrize("slots", [False, True])
@pytest.mark.parametrize("n", [1, 3, 9])
def test_platoon_sparse_path_matches_dense(topology, slots, n):
    if topology == "RING" and n < 3:
        pytest.skip("a ring needs 3 followers")
    rng = np.random.default_rng(n)
    sc = resolve_scenario("pereira2023", topology=topology, neighbour_slots=slots,
                          initial_state=rng.uniform(-60, 60, (n, 6)))
    dense, sparse = (PlatoonCore(sc, batch=3, method=m) for m in ("dense", "sparse"))
    assert dense.dense and not sparse.dense
    x = rng.uniform(-40, 40, (3, n, 6))
    x[2, -1] = x[2, 0] + [1.0, 0, 0, 0, 0, 0]  # a collision
    for core in (dense, sparse):
        core.reset(x)
    accel = rng.uniform(-1, 1, (3, n, 3))
    a, b = dense.step(accel), sparse.step(accel)
    for key in a.info:
        np.testing.assert_allclose(a.info[key], b.info[key], rtol=1e-12, atol=1e-12, err_msg=key)
    np.testing.assert_allclose(a.rewards, b.rewards, rtol=1e-12)
    np.testing.assert_array_equal(a.terminated, b.terminated)
    np.testing.assert_allclose(dense.observe(), sparse.observe(), atol=1e-6)
    if n > 1:
        assert a.info["collision"][2].any()


def test_swarm_generator_builds_large_envs():
    assert MAX_AGENTS >= 1024
    for formation, topology in (("chain", "TPLF"), ("ring", "RING")):
        env = satenv.make("platoon_v0", **swarm(200, formation, topology))
        assert not env.core.dense and env.core.obs_dim == 15 + 7 * 2
        obs, _ = env.reset(seed=1)
        assert env.scenario.collision_voids_success  # the swarm formation is collision-free
        obs, rewards, terms, truncs, infos = env.step({a: np.zeros(3) for a in env.agents})
        assert len(obs) == 200 and not any(terms.values())
        assert min(i["min_separation"] for i in infos.values()) > 2 * env.scenario.follower_radius


def test_swarm_rejects_unknown_formation():
    with pytest.raises(ValueError, match="formation"):
        swarm(8, "grid")


def test_ring_formation_is_evenly_spaced():
    sc = resolve_scenario("pereira2023", **{k: v for k, v in swarm(12, "ring", "RING").items() if k != "preset"})
    p = sc.desired_states()[:, :3]
    gaps = np.linalg.norm(p - np.roll(p, 1, axis=0), axis=1)
    np.testing.assert_allclose(gaps, 20.0)
    np.testing.assert_allclose(sc.desired_states()[:, 3:], 0.0)
