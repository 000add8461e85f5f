"""The edge fit's graph: its incidence products and its refilled Laplacian against explicit matrices."""
import numpy as np
from scipy import sparse

from estimator.light.edge_fit import EdgeGraph


def _incidence(i, j, faces):
    rows = np.tile(np.arange(len(i)), 2)
    return sparse.csr_matrix((np.r_[np.ones(len(i)), -np.ones(len(i))], (rows, np.r_[i, j])), shape=(len(i), faces))


def test_the_refilled_laplacian_is_b_transpose_w_b():
    """With repeated edges and a face on no edge, B^T diag(w) B to 1e-12, for two weightings
    of one graph (the pattern is built once)."""
    rng = np.random.default_rng(0)
    faces = 40
    i = rng.integers(0, faces - 1, 90)
    j = (i + rng.integers(1, 5, 90)) % (faces - 1)            # face faces-1 is on no edge
    i, j = np.r_[i, i[:5]], np.r_[j, j[:5]]                      # five edges twice
    graph, b = EdgeGraph(i, j, faces), _incidence(i, j, faces)
    for w in (rng.random(len(i)), rng.random(len(i)) * 10):
        expected = (b.T @ sparse.diags(w) @ b).toarray()
        np.testing.assert_allclose(graph.laplacian(w).toarray(), expected, atol=1e-12)


def test_difference_and_gather_are_b_and_its_transpose():
    """(E',) B x and (F,) B^T v, shapes and values, and <B x, v> = <x, B^T v>."""
    rng = np.random.default_rng(1)
    faces = 30
    i, j = rng.integers(0, faces, 50), rng.integers(0, faces, 50)
    graph, b = EdgeGraph(i, j, faces), _incidence(i, j, faces)
    x, v = rng.normal(size=faces), rng.normal(size=50)
    assert len(graph) == 50 and graph.difference(x).shape == (50,) and graph.gather(v).shape == (faces,)
    np.testing.assert_allclose(graph.difference(x), b @ x, atol=1e-12)
    np.testing.assert_allclose(graph.gather(v), b.T @ v, atol=1e-12)
    assert abs(graph.difference(x) @ v - x @ graph.gather(v)) < 1e-10
