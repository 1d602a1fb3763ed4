"""Hungarian target allocation (li2022 §3.3) and the cluster communication graph."""

import itertools

import numpy as np
import pytest

from satenv.allocation import allocation_cost, assignment_cost, hungarian_assignment
from satenv.cluster_graph import nearest_neighbour_graph
from satenv.scenarios.cluster import PRESETS


def brute_force(cost: np.ndarray) -> float:
    m, t = cost.shape
    return min(sum(cost[i, perm[i]] for i in range(m)) for perm in itertools.permutations(range(t), m))


@pytest.mark.parametrize("m,t", [(1, 1), (3, 3), (5, 5), (6, 6), (4, 6)])
def test_hungarian_is_optimal_against_brute_force(m, t):
    rng = np.random.default_rng(m * 10 + t)
    for _ in range(20):
        q = rng.uniform(-1000, 1000, (m, 3))
        tg = rng.uniform(-1000, 1000, (t, 3))
        alpha = rng.uniform(0.5, 2.0, m)
        a = hungarian_assignment(q, tg, alpha)
        assert len(set(a.tolist())) == m and a.min() >= 0 and a.max() < t   # one-to-one
        c = allocation_cost(q, tg, alpha)
        assert assignment_cost(c, a) == pytest.approx(brute_force(c), rel=1e-12)


def test_cost_matrix_definition_and_batching():
    q = np.array([[0.0, 0, 0], [10.0, 0, 0]])
    tg = np.array([[9.0, 0, 0], [1.0, 0, 0], [0.0, 3, 4]])
    c = allocation_cost(q, tg, alpha=2.0)
    np.testing.assert_allclose(c, 2.0 * np.array([[81, 1, 25], [1, 81, 125]]))
    assert hungarian_assignment(q, tg).tolist() == [1, 0]
    batch = hungarian_assignment(np.stack([q, q[::-1]]), tg)
    assert batch.tolist() == [[1, 0], [0, 1]]


def test_li2022_case1_allocation_beats_the_table_order():
    sc = PRESETS["li2022-case1"]
    q, tg = sc.initial_array()[:, :3], sc.targets_array()
    a = hungarian_assignment(q, tg)
    c = allocation_cost(q, tg)
    assert assignment_cost(c, a) <= assignment_cost(c, np.arange(10))
    assert sorted(a.tolist()) == list(range(10))


def test_allocation_errors():
    with pytest.raises(ValueError, match="at least as many targets"):
        hungarian_assignment(np.zeros((3, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"shape \(\.\.\., K, 3\)"):
        hungarian_assignment(np.zeros((3, 2)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="alpha"):
        allocation_cost(np.zeros((2, 3)), np.zeros((2, 3)), alpha=[1.0, -1.0])
    with pytest.raises(ValueError, match="finite"):
        allocation_cost(np.full((2, 3), np.nan), np.zeros((2, 3)))


def test_nearest_neighbour_graph():
    # five satellites on a line 100 m apart; N_a = 2, r_c = 150 m
    q = np.zeros((5, 3))
    q[:, 0] = np.arange(5) * 100.0
    directed = nearest_neighbour_graph(q, 2, 150.0, symmetric=False)
    assert directed.sum(axis=1).tolist() == [1, 2, 2, 2, 1]        # range limits the ends
    assert not directed.diagonal().any()
    full = nearest_neighbour_graph(q, 2, 1000.0, symmetric=False)
    assert full[0].tolist() == [False, True, True, False, False]
    sym = nearest_neighbour_graph(q, 2, 1000.0)
    np.testing.assert_array_equal(sym, sym.T)
    assert sym[4, 2] and sym[2, 4]                                 # union of the k-nearest lists
    assert nearest_neighbour_graph(q, 0, 1000.0).sum() == 0
    with pytest.raises(ValueError, match="n_nearest"):
        nearest_neighbour_graph(q, -1)
    with pytest.raises(ValueError, match="comm_range"):
        nearest_neighbour_graph(q, 2, 0.0)
