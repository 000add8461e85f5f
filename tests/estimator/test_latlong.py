import numpy as np
import pytest

from estimator.core import latlong


def test_mitsuba_envmap_orientation():
    d = latlong.directions(5, 8)
    np.testing.assert_allclose(d[0, 3], [0, 1, 0], atol=1e-12)        # top row = +Y
    np.testing.assert_allclose(d[-1, 0], [0, -1, 0], atol=1e-12)      # bottom row = -Y
    np.testing.assert_allclose(d[2, 4], [0, 0, 1], atol=1e-12)        # u = 0.5 -> +Z
    np.testing.assert_allclose(d[2, 2], [1, 0, 0], atol=1e-12)        # u = 0.25 -> +X
    np.testing.assert_allclose(d[2, 0], [0, 0, -1], atol=1e-12)       # u = 0 -> -Z


def test_uv_round_trip_and_bilinear_lookup_of_grid_points():
    h, w = 9, 16
    d = latlong.directions(h, w)
    uv = latlong.to_uv(d[1:-1].reshape(-1, 3))
    np.testing.assert_allclose(uv[:, 0] * w, np.tile(np.arange(w), h - 2), atol=1e-9)
    image = np.random.default_rng(0).random((h, w, 2))
    np.testing.assert_allclose(latlong.sample_bilinear(image, d[1:-1].reshape(-1, 3)),
                               image[1:-1].reshape(-1, 2), atol=1e-9)


def test_too_small_map_is_refused():
    with pytest.raises(ValueError, match="at least"):
        latlong.directions(2, 8)
