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


def test_downsampling_keeps_every_integral_and_the_low_orders():
    """Averaging onto a coarser grid keeps the map's integral over the sphere exactly (the
    cells' solid angles partition it, azimuth wrapping past 0) and its SH up to rounding of
    the finer cells (the box filter of 1.4 degree cells changes order 4 by < 1e-3)."""
    from estimator.core import latlong, sh

    rng = np.random.default_rng(0)
    noise = rng.random((200, 400, 3))
    for height, width in ((51, 100), (67, 133)):
        small = latlong.downsample(noise, height, width)
        assert small.shape == (height, width, 3)
        np.testing.assert_allclose((small * latlong.solid_angles(height, width)[..., None]).sum((0, 1)),
                                   (noise * latlong.solid_angles(200, 400)[..., None]).sum((0, 1)), rtol=1e-12)
    smooth = sh.to_latlong(rng.normal(size=(25, 3)), 513, 1024)
    np.testing.assert_allclose(sh.project_latlong(4, latlong.downsample(smooth, 129, 256)),
                               sh.project_latlong(4, smooth), atol=1e-3)


def test_projecting_a_wide_map_is_blockwise_and_bounded(monkeypatch):
    """Blocks of rows give the one-shot quadrature; a map wider than PROJECTION_WIDTH is
    averaged first (a sun pixel, averaged onto cells of 2.8 degrees, keeps its order-12
    coefficients within 5 % of the largest)."""
    from estimator.core import latlong, sh

    image = np.random.default_rng(1).random((33, 64, 3))
    full = (sh.basis(6, latlong.directions(33, 64).reshape(-1, 3))
            * latlong.solid_angles(33, 64).reshape(-1, 1)).T @ image.reshape(-1, 3)
    monkeypatch.setattr(sh, "PROJECTION_PIXELS", 100)
    np.testing.assert_allclose(sh.project_latlong(6, image), full, rtol=1e-12, atol=1e-14)
    sun = np.zeros((129, 256, 3))
    sun[40, 77] = 1e4
    reference = sh.project_latlong(12, sun)
    monkeypatch.setattr(sh, "PROJECTION_WIDTH", 128)
    np.testing.assert_allclose(sh.project_latlong(12, sun), reference, atol=0.05 * np.abs(reference).max())
