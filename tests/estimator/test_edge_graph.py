"""The edge fit's graph: its incidence products and its refilled Laplacian against explicit matrices."""
import numpy as np
from scipy import sparse

from estimator.core.edge_graph import EdgeGraph
from estimator.light.edge_fit import _light_block, _normal_equations


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


def test_the_scaled_laplacian_is_d_b_transpose_w_b_d():
    """laplacian(w, d) = D B^T diag(w) B D with D = diag(d), zeros in d included (faces outside
    the fit), to 1e-12."""
    rng = np.random.default_rng(2)
    faces = 25
    i = rng.integers(0, faces, 60)
    j = (i + rng.integers(1, 6, 60)) % faces
    graph, b = EdgeGraph(i, j, faces), _incidence(i, j, faces)
    w, d = rng.random(len(i)), rng.random(faces) * 3
    d[[3, 11]] = 0.0
    expected = (sparse.diags(d) @ b.T @ sparse.diags(w) @ b @ sparse.diags(d)).toarray()
    np.testing.assert_allclose(graph.laplacian(w, d).toarray(), expected, atol=1e-12)


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


def test_normal_equations_are_j_transpose_w_j_of_the_explicit_jacobian():
    """The edge fit's Gauss-Newton system, formed without its Jacobian, equals J^T W J and
    J^T W r of the explicit (E' + R', k + regions) Jacobian to 1e-10: edge rows -(g_i - g_j),
    region rows [-g_f, -e_r], g = c / shade per face and 0 outside the fit."""
    rng = np.random.default_rng(3)
    faces, k, regions = 30, 4, 3
    i = rng.integers(0, faces, 70)
    j = (i + rng.integers(1, 7, 70)) % faces
    graph = EdgeGraph(i, j, faces)
    columns = rng.random((faces, k))
    inverse_shade = 1.0 / (0.5 + rng.random(faces))
    inverse_shade[[2, 9]] = 0.0
    member = np.sort(rng.choice(faces, 18, replace=False))
    group = rng.integers(0, regions, len(member))
    weights, residual = rng.random(len(i) + len(member)), rng.normal(size=len(i) + len(member))
    block = _light_block(columns, inverse_shade, graph, member, weights)
    normal, gradient = _normal_equations(columns, inverse_shade, graph, member, group, regions, weights, residual,
                                         block)
    g = columns * inverse_shade[:, None]
    jacobian = np.zeros((len(i) + len(member), k + regions))
    jacobian[:len(i), :k] = -(g[i] - g[j])
    jacobian[len(i):, :k] = -g[member]
    jacobian[len(i) + np.arange(len(member)), k + group] = -1.0
    np.testing.assert_allclose(normal, jacobian.T @ (weights[:, None] * jacobian), atol=1e-10)
    np.testing.assert_allclose(gradient, jacobian.T @ (weights * residual), atol=1e-10)
    # edges alone (no region row): the light's block and gradient only
    edges_only = np.arange(len(i))
    none = np.zeros(0, int)
    block = _light_block(columns, inverse_shade, graph, none, weights[edges_only])
    normal, gradient = _normal_equations(columns, inverse_shade, graph, none, none, 0, weights[edges_only],
                                         residual[edges_only], block)
    jacobian = jacobian[:len(i), :k]
    np.testing.assert_allclose(normal, jacobian.T @ (weights[edges_only, None] * jacobian), atol=1e-10)
    np.testing.assert_allclose(gradient, jacobian.T @ (weights[edges_only] * residual[edges_only]), atol=1e-10)
