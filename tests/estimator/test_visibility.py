import numpy as np
import pytest

from estimator.core import sh
from estimator.core.data import TriangleMesh
from estimator.core.errors import InputError
from estimator.model.reflection import diffuse_matrix, lobe_matrix, mirror_matrix
from estimator.rays.raycast import RayCaster
from estimator.rays.visibility import compute_visibility, shadow_function, sphere_sampling

from .meshes import lobed, sphere


def test_paper_sphere_sampling():
    s = sphere_sampling(1164)
    assert s.directions.shape == (1164, 3) and s.weights.shape == (1164,)
    assert s.weights.sum() == pytest.approx(4 * np.pi)
    assert s.weights.min() > 0.5 * s.weights.mean() and s.weights.max() < 1.5 * s.weights.mean()
    # the quadrature integrates low-order SH: Y00 -> sqrt(4 pi), others -> 0
    integral = s.weights @ sh.basis(4, s.directions)
    assert integral[0] == pytest.approx(np.sqrt(4 * np.pi), rel=1e-6)
    assert np.abs(integral[1:]).max() < 5e-3  # 0.15 % of the DC integral (measured 0.004)


@pytest.mark.parametrize("count", [12, 301, 1164, 5000])
def test_nearest_direction_is_exact(count):
    # the grid lookup against a k-d tree: random directions, not normalised, the samples
    # themselves, the poles and the seam at phi = +-pi
    from scipy.spatial import cKDTree

    s = sphere_sampling(count)
    rng = np.random.default_rng(count)
    seam = np.stack([np.cos(np.linspace(-1.5, 1.5, 50)), np.full(50, -1e-12), np.sin(np.linspace(-1.5, 1.5, 50))], 1)
    d = np.concatenate([rng.standard_normal((20000, 3)) * rng.uniform(0.1, 10.0, (20000, 1)), s.directions,
                        [[0, 0, 1], [0, 0, -1], [0, 1e-9, 1], [-1, 0, 0]], seam])
    np.testing.assert_array_equal(s.nearest(d), cKDTree(s.directions).query(d)[1])
    with pytest.raises(InputError, match="must be finite"):
        s.nearest(np.array([[np.nan, 0.0, 1.0]]))


def test_nearest_direction_of_samples_that_leave_a_hemisphere_empty():
    # directions that do not surround the origin have no covering radius: the k-d tree answers
    from estimator.rays.visibility import SphereSampling, nearest_candidates

    upper = sphere_sampling(400).directions
    upper = upper[upper[:, 2] > 0.1]
    assert nearest_candidates(upper) is None
    s = SphereSampling(upper, np.ones(len(upper)))
    d = np.random.default_rng(0).standard_normal((500, 3))
    assert np.all(np.sum(upper[s.nearest(d)] * d, axis=1) >= (d @ upper.T).max(axis=1) - 1e-12)


def test_convex_sphere_sees_its_whole_upper_hemisphere():
    mesh = sphere(2)
    s = sphere_sampling(300)
    vis = compute_visibility(RayCaster(mesh), s)
    upper = mesh.face_normals @ s.directions.T > 0
    np.testing.assert_array_equal(vis.unpack(slice(None)), upper)
    faces = np.array([0, 5, 7])
    dirs = np.array([3, 100, 299])
    np.testing.assert_array_equal(vis.lookup(faces, dirs), upper[faces, dirs])


def test_chunking_does_not_change_the_result_and_concave_faces_are_shadowed():
    mesh = lobed(3, lobes=4)
    s = sphere_sampling(200)
    caster = RayCaster(mesh)
    a = compute_visibility(caster, s)
    b = compute_visibility(caster, s, max_rays=300 * 200)   # chunks of 300 faces: 1280 = 4 x 300 + 80
    assert mesh.num_faces % 300 != 0                         # the last chunk is a partial one
    np.testing.assert_array_equal(a.bits, b.bits)
    upper = mesh.face_normals @ s.directions.T > 0
    shadowed = (upper & ~a.unpack(slice(None))).sum(axis=1)
    assert shadowed.max() > 5 and (shadowed > 0).mean() > 0.1  # valleys shadow themselves


def test_the_shadow_function_is_computed_once_per_caster_and_sampling():
    mesh = lobed(3, lobes=4)
    caster = RayCaster(mesh)
    first = shadow_function(caster, sphere_sampling(200))
    assert shadow_function(caster, sphere_sampling(200)) is first                # kept on the caster
    np.testing.assert_array_equal(first.bits, compute_visibility(caster, sphere_sampling(200)).bits)
    assert not first.bits.flags.writeable                                        # shared: read-only
    other = shadow_function(caster, sphere_sampling(300))
    assert other is not first and other.num_directions == 300
    assert shadow_function(RayCaster(mesh), sphere_sampling(200)) is not first  # another caster, its own


def test_unshadowed_diffuse_matrix_is_the_clamped_cosine():
    # one upward triangle alone: C_lm = (A_l / pi) Y_lm(n), A = (pi, 2pi/3, pi/4)
    mesh = TriangleMesh(np.array([[0, 0, 0], [1, 0, 0], [0, 0, -1.0]]), np.array([[0, 1, 2]]))
    assert np.allclose(mesh.face_normals[0], [0, 1, 0])
    s = sphere_sampling(1164)
    c = diffuse_matrix(mesh, s, compute_visibility(RayCaster(mesh), s), 2)
    expected = sh.expand_per_degree(np.array([1.0, 2 / 3, 1 / 4])) * sh.basis(2, mesh.face_normals)[0]
    np.testing.assert_allclose(c[0], expected, atol=3e-3)


def test_mirror_and_lobe_matrices_on_a_plane():
    mesh = TriangleMesh(np.array([[0, 0, 0], [1, 0, 0], [0, 0, -1.0]]), np.array([[0, 1, 2]]))
    s = sphere_sampling(1164)
    vis = compute_visibility(RayCaster(mesh), s)
    r = np.array([[0.0, 1.0, 0.0], [np.sin(1.4), np.cos(1.4), 0.0]])
    faces = np.zeros(2, int)
    np.testing.assert_allclose(mirror_matrix(faces, r, s, vis, 3), sh.basis(3, r), atol=1e-12)
    # a whole lobe (r = normal) filters the radiance by the Phong filter (Funk-Hecke) ...
    e = lobe_matrix(faces, r, s, vis, 6, 10.0)
    filtered = sh.expand_per_degree(sh.phong_filter(6, 10.0)) * sh.basis(6, r[:1])[0]
    np.testing.assert_allclose(e[0], filtered, atol=0.01)
    # ... a lobe 80 degrees off the normal is cut by the horizon: less energy in the DC term
    assert 0.5 * filtered[0] < e[1, 0] < 0.9 * filtered[0]
