"""The UV atlas and per-face texture means: Mitsuba's bitmap lookup, exact on linear textures."""
import numpy as np
import pytest

from estimator.core.atlas import barycentric_grid, face_means, sample_bilinear, uv_atlas
from estimator.core.errors import InputError
from estimator.rays import backend
from harness.scene.geometry import icosphere


def test_bilinear_lookup_is_mitsubas_bitmap():
    """Against Mitsuba's own ``bitmap`` (bilinear, clamp, raw), inside and outside [0, 1].

    ``accel`` is off: on ``cuda_ad_rgb`` the default samples through the GPU's texture units,
    whose bilinear weights are 8-bit fixed point (errors up to 3e-3 here), not float arithmetic.
    """
    mi = backend.set_variant()
    rng = np.random.default_rng(0)
    texture = rng.random((5, 7, 3)).astype(np.float32)
    bitmap = mi.load_dict({"type": "bitmap", "data": mi.TensorXf(texture), "raw": True,
                           "filter_type": "bilinear", "wrap_mode": "clamp", "accel": False})
    uv = rng.random((300, 2)) * 1.2 - 0.1
    si = mi.SurfaceInteraction3f()
    si.uv = mi.Point2f(uv[:, 0].astype(np.float32), uv[:, 1].astype(np.float32))
    theirs = np.array(bitmap.eval(si))
    theirs = theirs.T if theirs.shape[0] == 3 else theirs
    np.testing.assert_allclose(sample_bilinear(texture.astype(np.float64), uv), theirs, atol=1e-5)


@pytest.mark.parametrize("k", [1, 2, 5])
def test_barycentric_grid_tiles_the_triangle(k):
    points = barycentric_grid(k)
    assert points.shape == (k * k, 3)
    np.testing.assert_allclose(points.sum(axis=1), 1.0)
    assert points.min() > 0                                   # sub-triangle centroids lie inside
    np.testing.assert_allclose(points.mean(axis=0), 1 / 3)    # equal areas: the mean is the centroid
    assert len(np.unique(np.round(points, 12), axis=0)) == k * k
    with pytest.raises(InputError, match="k >= 1"):
        barycentric_grid(0)


def test_face_means_are_exact_on_a_linear_texture():
    """A texture linear in uv is linear under bilinear lookup (away from the clamped border
    half-texel), so a face's mean is its value at the face's UV centroid."""
    size = 64
    centres = (np.arange(size) + 0.5) / size
    u, v = np.meshgrid(centres, centres)                       # row i holds v = (i + 0.5) / size
    texture = np.stack([u, v, 0.3 + 0.2 * u - 0.1 * v], axis=-1)
    mesh = icosphere(2)
    vertices, faces, uv = uv_atlas(mesh)
    uv = 0.1 + 0.8 * uv                                        # inside the linear part
    means = face_means(texture, faces, uv)
    centroid = uv[faces].mean(axis=1)
    np.testing.assert_allclose(means, np.column_stack([centroid, 0.3 + 0.2 * centroid[:, 0] - 0.1 * centroid[:, 1]]),
                               atol=1e-12)
    assert means.shape == (mesh.num_faces, 3)
