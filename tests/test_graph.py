"""satenv.graph: named topologies, validation, Laplacians and the neighbourhood error (eq. 9-12)."""

import numpy as np
import pytest

from satenv.graph import TOPOLOGIES, Topology, make_topology, named_adjacency, neighbourhood_error

# a_ij = 1 iff follower i hears follower j (rows receive, columns send).
EXPECTED_4 = {
    "PLF": [[0, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]],
    "BDL": [[0, 1, 0, 0], [1, 0, 1, 0], [0, 1, 0, 1], [0, 0, 1, 0]],
    "TPLF": [[0, 0, 0, 0], [1, 0, 0, 0], [1, 1, 0, 0], [0, 1, 1, 0]],
    "RING": [[0, 1, 0, 1], [1, 0, 1, 0], [0, 1, 0, 1], [1, 0, 1, 0]],  # satenv's swarm graph
}


@pytest.mark.parametrize("name", TOPOLOGIES)
def test_named_topologies_match_zheng2017(name):
    topo = make_topology(name, 4)
    np.testing.assert_array_equal(topo.adjacency, EXPECTED_4[name])
    np.testing.assert_array_equal(topo.pinning, np.ones(4))
    np.testing.assert_array_equal(topo.degrees, np.sum(EXPECTED_4[name], axis=1))
    np.testing.assert_array_equal(topo.gains, 1 + np.sum(EXPECTED_4[name], axis=1))
    lbar = np.eye(4) + np.diag(np.sum(EXPECTED_4[name], axis=1)) - np.array(EXPECTED_4[name])
    np.testing.assert_array_equal(topo.augmented_laplacian, lbar)
    np.testing.assert_array_equal(topo.G + topo.D - topo.adjacency, lbar)
    np.testing.assert_array_equal(topo.laplacian, lbar - np.eye(4))
    assert topo.name == name


def test_lowercase_name_and_larger_platoons():
    assert make_topology("tplf", 6).name == "TPLF"
    adj = named_adjacency("TPLF", 6)
    assert adj[5, 4] == adj[5, 3] == 1 and adj[5].sum() == 2
    assert named_adjacency("BDL", 1).shape == (1, 1)


def _explicit_error(x, adj, g):
    """E_f = sum_{i in N_f}(x_f - x_i) + g_f x_f, written as the paper's sum."""
    out = np.zeros_like(x)
    for f in range(adj.shape[0]):
        out[..., f, :] = g[f] * x[..., f, :]
        for i in range(adj.shape[0]):
            if adj[f, i]:
                out[..., f, :] += x[..., f, :] - x[..., i, :]
    return out


@pytest.mark.parametrize("name", TOPOLOGIES)
def test_neighbourhood_error_batched_matches_eq9(name):
    rng = np.random.default_rng(0)
    topo = make_topology(name, 5)
    x = rng.normal(size=(7, 3, 5, 6))
    expect = _explicit_error(x, topo.adjacency, topo.pinning)
    np.testing.assert_allclose(neighbourhood_error(x, topo), expect, atol=1e-12)
    np.testing.assert_allclose(topo.neighbourhood_error(x[0, 0]), expect[0, 0], atol=1e-12)


def test_edge_direction_convention():
    # follower 2 hears follower 1 (edge 1 -> 2): a_21 = 1; follower 1 hears nobody.
    topo = make_topology([[0, 0], [1, 0]])
    x = np.array([[1.0, 0, 0, 0, 0, 0], [5.0, 0, 0, 0, 0, 0]])
    e = topo.neighbourhood_error(x)
    assert e[0, 0] == 1.0                      # g x_1
    assert e[1, 0] == (5.0 - 1.0) + 5.0        # (x_2 - x_1) + g x_2
    np.testing.assert_array_equal(topo.neighbours(1), [0])
    assert topo.neighbours(0).size == 0


def test_desired_states_of_table1():
    e_d = np.array([0, -8.0, 0, 0, 0, 0])
    topo = make_topology("PLF", 4)
    xs = topo.desired_states(e_d)
    np.testing.assert_allclose(xs[:, 1], [-8, -12, -14, -15])
    np.testing.assert_allclose(topo.neighbourhood_error(xs), topo.gains[:, None] * e_d, atol=1e-12)


@pytest.mark.parametrize("name", TOPOLOGIES)
def test_proposition2_gd_lbar_has_positive_eigenvalues(name):
    topo = make_topology(name, 6)
    eig = np.linalg.eigvals((topo.G + topo.D) @ topo.augmented_laplacian)
    assert np.all(eig.real > 0)


@pytest.mark.parametrize(
    "adj, match",
    [
        (np.zeros((2, 3)), "square"),
        ([[0, 2], [1, 0]], "0 or 1"),
        ([[1, 0], [1, 0]], "zero diagonal"),
        ([[0, 0.5], [1, 0]], "0 or 1"),
        (np.zeros((0, 0)), "square"),
    ],
)
def test_bad_adjacency_rejected(adj, match):
    with pytest.raises(ValueError, match=match):
        make_topology(adj)


def test_pinning_must_reach_every_follower():
    with pytest.raises(ValueError, match=r"every follower must hear the leader.*\[2\]"):
        make_topology([[0, 0], [1, 0]], pinning=[1, 0])
    with pytest.raises(ValueError, match="shape"):
        make_topology([[0, 0], [1, 0]], pinning=[1, 1, 1])
    with pytest.raises(ValueError, match="0 or 1"):
        Topology(adjacency=np.zeros((2, 2)), pinning=np.array([1, 3]))


def test_other_bad_inputs():
    with pytest.raises(ValueError, match="unknown topology"):
        make_topology("STAR", 3)
    with pytest.raises(ValueError, match="n_followers"):
        make_topology("PLF")
    with pytest.raises(ValueError, match="positive int"):
        named_adjacency("PLF", 0)
    with pytest.raises(ValueError, match="4 followers"):
        make_topology(np.zeros((3, 3)), 4)
    with pytest.raises(ValueError, match="numeric"):
        make_topology([["a", "b"], ["c", "d"]])
    with pytest.raises(ValueError, match=r"\(\.\.\., 4, d\)"):
        neighbourhood_error(np.zeros((3, 6)), make_topology("PLF", 4))


def test_arrays_are_read_only():
    topo = make_topology("PLF", 3)
    with pytest.raises(ValueError):
        topo.adjacency[0, 1] = 1
    with pytest.raises(ValueError):
        topo.augmented_laplacian[0, 0] = 5.0
