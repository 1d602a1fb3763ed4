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


# ---------------------------------------------------------------------------------------- cluster
from satenv.cluster_graph import in_range_nearest, nearest_neighbour_graph, neighbour_lists  # noqa: E402
from satenv.envs.cluster_v0 import ClusterCore  # noqa: E402
from satenv.scenarios import cluster as cluster_sc  # noqa: E402


@pytest.mark.parametrize("m", [1, 2, 6, 40])
def test_cluster_neighbour_lists_match_adjacency(m):
    rng = np.random.default_rng(m)
    pos = rng.uniform(-1500, 1500, (3, m, 3))
    adj = nearest_neighbour_graph(pos, 4, 1000.0)
    lists = neighbour_lists(pos, 4, 1000.0)
    rebuilt = np.zeros_like(adj)
    for b, i, s in zip(*np.nonzero(lists >= 0), strict=True):
        rebuilt[b, i, lists[b, i, s]] = True
    np.testing.assert_array_equal(rebuilt, adj)
    directed = nearest_neighbour_graph(pos, 4, 1000.0, symmetric=False)
    dist, index = in_range_nearest(pos, 4, 1000.0)
    assert (np.diff(np.minimum(dist, 1e300), axis=-1) >= 0).all()   # nearest first
    for b, i, s in zip(*np.nonzero(index >= 0), strict=True):
        assert directed[b, i, index[b, i, s]]
    np.testing.assert_array_equal((index >= 0).sum(-1), directed.sum(-1))


def _cluster_cores(m, rng, speed):
    sc = cluster_sc.resolve_scenario("li2022-case1", initial_positions=rng.uniform(-1500, 1500, (m, 3)),
                                     targets=rng.uniform(-1500, 1500, (m, 3)), disturbance="random",
                                     terminate_on_collision=False)
    cores = [ClusterCore(sc, batch=3, method=method) for method in ("dense", "sparse")]
    assert cores[0].dense and not cores[1].dense
    x = np.zeros((3, m, 6))
    x[..., :3] = rng.uniform(-1500, 1500, (3, m, 3))
    x[..., 3:] = rng.uniform(-speed, speed, (3, m, 3))
    if m > 1:
        x[2, -1, :3] = x[2, 0, :3] + [150.0, 0, 0]   # a pair within 2 r_s
    return cores, x


@pytest.mark.parametrize("m", [1, 2, 5, 40])
@pytest.mark.parametrize("speed", [2.0, 150.0])  # candidates hold / copies searched again
def test_cluster_sparse_path_matches_dense(m, speed):
    rng = np.random.default_rng(m)
    cores, x = _cluster_cores(m, rng, speed)
    infos = [core.reset(x.copy()) for core in cores]
    for key in infos[0]:
        np.testing.assert_allclose(infos[0][key], infos[1][key], rtol=1e-12, err_msg=key)
    accel = rng.uniform(-0.02, 0.02, (3, m, 3))
    a, b = (core.step(accel, rng=np.random.default_rng(1)) for core in cores)
    for key in a.info:
        np.testing.assert_allclose(a.info[key], b.info[key], rtol=1e-12, err_msg=key)
    np.testing.assert_allclose(a.rewards, b.rewards, rtol=1e-12)
    np.testing.assert_allclose(cores[0].observe(), cores[1].observe(), atol=1e-6)
    if m > 1:
        assert a.info["collision"][2, 0]
        assert (a.info["n_neighbours"] > 0).any()


def test_cluster_sparse_pair_minimum_is_exact_within_the_decision():
    """The nearest satellite changes inside a decision: two satellites fly through each other."""
    sc = cluster_sc.resolve_scenario("li2022-case1", disturbance="none", dynamics="cw",
                                     terminate_on_collision=False)
    core = ClusterCore(sc, batch=1, method="sparse")
    x = np.zeros((1, 10, 6))
    x[0, :, :3] = sc.initial_array()[:, :3]
    x[0, 1, :3] = x[0, 0, :3] + [0.0, 60.0, 0.0]
    x[0, 1, 3:] = [0.0, -24.0, 0.0]   # passes satellite 0 after 2.5 s
    core.reset(x)
    info = core.step(np.zeros((1, 10, 3))).info
    assert info["pair_distance"][0, 0] < 1.0 < info["pair_distance"][0, 2]


def test_apf_neighbour_lists_match_dense(monkeypatch):
    from satenv.baselines import apf

    rng = np.random.default_rng(3)
    env = satenv.make("cluster_v0", initial_positions=rng.uniform(-900, 900, (40, 3)),
                      targets=rng.uniform(-900, 900, (40, 3)), terminate_on_collision=False)
    env.reset(seed=0)
    policy = apf.APF(env)
    sparse = policy._law()
    monkeypatch.setattr(apf, "DENSE_MAX", 64)
    dense = policy._law()
    np.testing.assert_allclose(sparse, dense, rtol=1e-12, atol=1e-15)
    assert np.abs(dense - policy._law()).max() == 0.0


def test_cluster_swarm_generator():
    kwargs = cluster_sc.swarm(300, dynamics="cw")
    env = satenv.make("cluster_v0", **kwargs)
    sc = env.scenario
    assert sc.n_agents == len(sc.targets) == 300 and sc.randomize and sc.dynamics == "cw"
    assert not env.core.dense
    env.reset(seed=2)
    a = env.assignment
    assert sorted(a.tolist()) == list(range(300))       # a permutation of the slots
    from satenv.allocation import allocation_cost, assignment_cost, hungarian_assignment

    cost = allocation_cost(env.state()[:1800].reshape(300, 6)[:, :3], env.core.all_targets[0])
    assert assignment_cost(cost, a) == pytest.approx(assignment_cost(cost, hungarian_assignment(
        env.state()[:1800].reshape(300, 6)[:, :3], env.core.all_targets[0])))
    slots = env.core.all_targets[0]
    gaps = np.linalg.norm(slots - sc.target_spacecraft, axis=-1)
    np.testing.assert_allclose(gaps, sc.random_target_radius)
    assert nearest(slots[None], 1)[0].min() >= sc.pair_distance + 10.0
    small = cluster_sc.resolve_scenario(**{k: v for k, v in cluster_sc.swarm(9).items() if k != "preset"})
    assert small.random_target_radius == 300.0       # li2022's sphere up to 9 satellites
    with pytest.raises(ValueError, match="swarm size"):
        cluster_sc.swarm(1025)


def test_apf_runs_on_a_cluster_swarm():
    from satenv import baselines
    env = satenv.make("cluster_v0", **cluster_sc.swarm(64, dynamics="cw", disturbance="none"))
    obs, _ = env.reset(seed=0)
    policy = baselines.make("apf", env)
    policy.reset(seed=0)
    start = np.linalg.norm(env.targets() - env.state()[:64 * 6].reshape(64, 6)[:, :3], axis=-1)
    for _ in range(20):
        obs, rewards, terms, truncs, infos = env.step(policy.act(obs))
    assert not any(terms.values())
    end = np.linalg.norm(env.targets() - env.state()[:64 * 6].reshape(64, 6)[:, :3], axis=-1)
    assert end.mean() < start.mean() - 50.0


# -------------------------------------------------------------------------------------- formation
from satenv.envs.formation_v0 import FormationCore  # noqa: E402
from satenv.neighbours import pairs_within  # noqa: E402
from satenv.scenarios.formation import resolve_scenario as formation_scenario  # noqa: E402


def test_pairs_within_matches_brute_force():
    rng = np.random.default_rng(0)
    pos = rng.uniform(-300, 300, (3, 30, 3))
    pairs = {tuple(p) for p in pairs_within(pos, 150.0).tolist()}
    d = np.linalg.norm(pos[:, :, None] - pos[:, None], axis=-1)
    brute = {(b * 30 + i, b * 30 + j) for b, i, j in zip(*np.nonzero(d <= 150.0), strict=True) if i < j}
    assert pairs == brute


@pytest.mark.parametrize("m", [1, 2, 7, 40])
def test_formation_sparse_path_matches_dense(m):
    rng = np.random.default_rng(m)
    sc = formation_scenario("kannan2022-position", initial_state=np.zeros((m, 6)), offsets=np.zeros((m, 3)),
                            goals=[tuple(g) for g in rng.uniform(-200, 200, (m, 3))],
                            collision_distance=5.0, terminate_on_collision=False)
    cores = [FormationCore(sc, batch=4, method=method) for method in ("dense", "sparse")]
    x = np.zeros((4, m, 6))
    x[..., :3] = rng.uniform(-150 * m ** (1 / 3), 150 * m ** (1 / 3), (4, m, 3))
    x[0, :, :3] *= 0.01       # one copy connected, the others (probably) split
    if m > 1:
        x[1, -1, :3] = x[1, 0, :3] + [2.0, 0, 0]
    for core in cores:
        core.reset(x.copy())
    accel = rng.uniform(-1, 1, (4, m, 3))
    a, b = (core.step(accel) for core in cores)
    for key in a.info:
        np.testing.assert_allclose(a.info[key], b.info[key], rtol=1e-12, err_msg=key)
    np.testing.assert_allclose(cores[0].observe(), cores[1].observe())
    assert a.info["connected"][0].all()
    if m > 6:
        assert not a.info["connected"][1:].all() and a.info["violations"].any()
