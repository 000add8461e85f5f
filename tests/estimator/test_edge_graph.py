"""The edge fit's graph: its incidence products and its refilled Laplacian against explicit matrices."""
import numpy as np
from scipy import sparse

from estimator.core.edge_graph import EdgeGraph
from estimator.light.edge_fit import _light_block, _normal_equations, _region_pattern


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


def test_the_laplacian_of_distinct_edges_is_written_in_place():
    """A mesh's edges (each face pair once, no loop) take the path that writes each entry in
    place: D (B^T diag(w) B + diag(r)) D to 1e-12, with zeros in d and a face on no edge."""
    rng = np.random.default_rng(4)
    faces = 36
    grid = np.arange(35).reshape(5, 7)                           # face 35 is on no edge
    i = np.r_[grid[:, :-1].ravel(), grid[:-1, :].ravel()]
    j = np.r_[grid[:, 1:].ravel(), grid[1:, :].ravel()]
    graph, b = EdgeGraph(i, j, faces), _incidence(i, j, faces)
    assert graph._distinct
    w, d, r = rng.random(len(i)), rng.random(faces) * 3, rng.random(faces)
    d[[3, 20]] = 0.0
    expected = (sparse.diags(d) @ (b.T @ sparse.diags(w) @ b + sparse.diags(r)) @ sparse.diags(d)).toarray()
    np.testing.assert_allclose(graph.laplacian(w, d, r).toarray(), expected, atol=1e-12)
    np.testing.assert_allclose(graph.laplacian(w).toarray(), (b.T @ sparse.diags(w) @ b).toarray(), atol=1e-12)


def test_the_in_place_laplacian_is_bit_for_bit_the_summed_one():
    """On distinct edges the entries written in place equal, bit for bit, those summed per slot
    (the path of repeated pairs), for weights, scales (zeros included) and a diagonal; a loop
    (an edge from a face to itself) or a pair listed both ways takes the summed path."""
    rng = np.random.default_rng(6)
    faces = 30
    i = np.arange(faces - 1)
    j = i + 1
    graph = EdgeGraph(i, j, faces)
    w, d, r = rng.random(len(i)) * 5, rng.random(faces) * 2, rng.random(faces)
    d[[0, 7]] = 0.0
    degree = np.bincount(i, w, faces) + np.bincount(j, w, faces) + r
    summed = np.bincount(graph._slot, np.concatenate([degree, -w, -w]), graph._pattern.nnz)
    summed *= d[graph._pattern_rows] * d[graph._pattern.indices]
    np.testing.assert_array_equal(graph.laplacian(w, d, r).data, summed)
    assert not EdgeGraph(np.r_[i, 3], np.r_[j, 3], faces)._distinct           # a loop
    assert not EdgeGraph(np.r_[i, 5], np.r_[j, 4], faces)._distinct           # (4, 5) and (5, 4)


def test_graphs_of_equal_edges_are_shared():
    """EdgeGraph.of builds a graph once per distinct edge set among the last few: equal arrays
    (other objects) give the same graph, other edges or another face count a new one, and a
    set pushed out by four others is built again."""
    i, j = np.array([0, 1, 2]), np.array([1, 2, 3])
    first = EdgeGraph.of(i, j, 4)
    assert EdgeGraph.of(i.copy(), j.copy(), 4) is first
    assert EdgeGraph.of(i, j, 5) is not first
    assert EdgeGraph.of(i, np.array([1, 2, 0]), 4) is not first
    for extra in range(4):
        EdgeGraph.of(np.array([extra]), np.array([extra + 1]), 9)
    again = EdgeGraph.of(i, j, 4)
    assert again is not first and len(again) == 3 and again.faces == 4
    i[0] = 2                                                     # the caller's array changes later
    np.testing.assert_array_equal(EdgeGraph.of(np.array([0, 1, 2]), j, 4).i, [0, 1, 2])


def test_the_shared_graphs_are_bounded_in_bytes(monkeypatch):
    """A graph larger than the cache's byte bound is built and returned but not kept, and the
    kept graphs stay within the bound."""
    from estimator.core import edge_graph
    monkeypatch.setattr(edge_graph, "_RECENT_BYTES", 20_000)
    small = EdgeGraph.of(np.array([0]), np.array([1]), 2)
    big = EdgeGraph.of(np.arange(999), np.arange(1, 1000), 1000)
    assert big.nbytes > 20_000 and len(big) == 999
    assert EdgeGraph.of(np.arange(999), np.arange(1, 1000), 1000) is not big
    assert sum(g.nbytes for g in edge_graph._RECENT.values()) <= 20_000
    assert EdgeGraph.of(np.array([0]), np.array([1]), 2) is small


def test_the_region_pattern_is_the_matrix_of_its_pairs():
    """_region_pattern's entries, refilled through its order, give the (R, F) matrix built from
    the (group, member) pairs, bit for bit in its stored arrays."""
    rng = np.random.default_rng(5)
    faces, regions = 50, 4
    member = np.sort(rng.choice(faces, 30, replace=False))
    group = rng.integers(0, regions, 30)
    values = rng.random(30)
    order, pattern = _region_pattern(member, group, regions, faces)
    refilled = sparse.csr_matrix((values[order], pattern.indices, pattern.indptr), shape=pattern.shape)
    built = sparse.csr_matrix((values, (group, member)), shape=(regions, faces))
    np.testing.assert_array_equal(refilled.indptr, built.indptr)
    np.testing.assert_array_equal(refilled.indices, built.indices)
    np.testing.assert_array_equal(refilled.data, built.data)


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
                                         block, _region_pattern(member, group, regions, faces))
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
                                         residual[edges_only], block, _region_pattern(none, none, 0, faces))
    jacobian = jacobian[:len(i), :k]
    np.testing.assert_allclose(normal, jacobian.T @ (weights[edges_only, None] * jacobian), atol=1e-10)
    np.testing.assert_allclose(gradient, jacobian.T @ (weights[edges_only] * residual[edges_only]), atol=1e-10)
