"""Pixels as equations in the faces they cover (estimator.pipeline.footprints)."""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import lsqr

from estimator.core.camera import Camera, look_at
from estimator.core.data import View
from estimator.pipeline.footprints import Footprints, footprint_radiance, pixel_shares, unmixed_rows
from estimator.pipeline.observations import gather_observations
from estimator.rays.raycast import RayCaster

from .meshes import sphere


def test_pixel_shares_count_the_sub_pixel_rays_per_face():
    ids = np.array([[0, 0, 0, 0], [1, 2, 2, 2], [3, 1, 3, 1]])
    shares = pixel_shares(ids, 5).toarray()
    assert shares.shape == (3, 5)
    np.testing.assert_allclose(shares.sum(axis=1), 1.0)
    np.testing.assert_allclose(shares, [[1, 0, 0, 0, 0], [0, 0.25, 0.75, 0, 0], [0, 0.5, 0, 0.5, 0]])


def _mixed_pixels(faces: int, views: int, rng) -> tuple[sp.csr_matrix, np.ndarray]:
    """(P, F) shares of pixels, each half one random face and the rest up to seven others
    (sixteen sub-pixel rays), ``views`` grids of two pixels per face, and (P,) each pixel's view."""
    rows, owner = [], []
    for v in range(views):
        ids = rng.integers(0, faces, size=(2 * faces, 16))
        ids[:, 8:] = ids[:, :1]                           # one face holds half of each pixel
        rows.append(pixel_shares(ids, faces))
        owner.append(np.full(2 * faces, v))
    return sp.vstack(rows).tocsr(), np.concatenate(owner)


def test_the_faces_radiance_is_recovered_from_pixels_that_mix_them_despite_highlights():
    """Pixels that mix several faces, with a highlight (5x the level) on 5 % of them: the
    absolute-deviation solve returns every face's radiance within 2 % (the median face within
    0.2 %); their footprint mean (what a pixel centre gives) and least squares are far off."""
    rng = np.random.default_rng(0)
    shares, view = _mixed_pixels(200, 12, rng)
    truth = rng.uniform(0.05, 1.0, size=(200, 3))
    rgb = shares @ truth
    glint = rng.random(len(rgb)) < 0.05
    rgb[glint] += 5.0
    radiance, area = footprint_radiance(Footprints(shares, rgb, view))
    np.testing.assert_allclose(area, np.asarray(shares.sum(axis=0)).ravel())
    np.testing.assert_allclose(radiance, truth, rtol=0.02)
    assert np.median(np.abs(radiance / truth - 1)) < 0.002
    least_squares = lsqr(shares, rgb[:, 0])[0]
    assert np.max(np.abs(least_squares / truth[:, 0] - 1)) > 0.2
    blurred = (shares.T @ rgb) / area[:, None]
    assert np.max(np.abs(blurred / truth - 1)) > 0.5


def test_an_unmixed_row_is_the_face_radiance_plus_its_pixels_view_dependent_light():
    """Pixels of one view share a view-dependent offset (a coat's sheen): each face's row in
    that view is its radiance plus that offset exactly, wherever its pixels mix faces; each
    (face, view) pair a sub-pixel ray hits gives one row, with the pixel area the face covers."""
    rng = np.random.default_rng(1)
    shares, view = _mixed_pixels(50, 4, rng)
    truth = rng.uniform(0.1, 1.0, size=(50, 3))
    offset = rng.uniform(0.0, 0.3, size=(4, 3))
    rgb = shares @ truth + offset[view]
    face, row_view, colour, share = unmixed_rows(Footprints(shares, rgb, view), truth)
    np.testing.assert_allclose(colour, truth[face] + offset[row_view], rtol=1e-12)
    area = np.stack([np.asarray(shares[view == v].sum(axis=0)).ravel() for v in range(4)])   # (views, faces)
    np.testing.assert_array_equal(np.sort(row_view * 50 + face), np.nonzero(area.ravel() > 0)[0])
    np.testing.assert_allclose(share, area[row_view, face], rtol=1e-12)
    assert np.all(np.diff(row_view * 50 + face) > 0)                                   # sorted by view, then face


def test_faces_smaller_than_a_pixel_are_unmixed_from_box_filtered_views():
    """Views rendered as a box filter would (each pixel the mean of 8 x 8 sub-pixel rays' face
    colours) of a sphere of faces smaller than a pixel, every face a random colour: with 4 x 4
    sub-pixel rays the median face's rows come back within 3 % of its own colour; through its
    pixel centres (``subpixel_samples=1``: the footprint's mean over the face and its
    neighbours) it is over 15 % off, and the 90th percentile error is over twice as large.
    Beyond ``max_pixels`` usable pixels the faces are observed through their pixel centres."""
    mesh = sphere(3)                                                 # 1,280 faces
    caster = RayCaster(mesh)
    rng = np.random.default_rng(2)
    colour = rng.uniform(0.1, 1.0, size=(mesh.num_faces, 3))
    eyes = [[0, 0, 4], [0.3, 0.2, 4], [-0.2, 0.35, 4], [0.15, -0.3, 4], [4, 0, 0.5], [0, 4, 0.3]]
    views = []
    for i, eye in enumerate(eyes):
        cam = Camera.from_fov(look_at(eye, [0, 0, 0]), 30, 40, 40)
        fine = caster.subpixel_faces(cam, 8, np.arange(40 * 40))        # (P, 64)
        image = np.where(fine[..., None] >= 0, colour[np.maximum(fine, 0)], 0.0).mean(axis=1)
        views.append(View(f"v{i}", cam, image.reshape(40, 40, 3).astype(np.float32)))
    errors = {}
    for samples in (1, 4):
        obs = gather_observations(caster, views, subpixel_samples=samples)
        assert obs.unresolved is not None
        unresolved = obs.unresolved[obs.face]
        errors[samples] = np.abs(obs.rgb[unresolved] / colour[obs.face[unresolved]] - 1)
    assert np.median(errors[4]) < 0.03 < 0.15 < np.median(errors[1])
    assert 2 * np.percentile(errors[4], 90) < np.percentile(errors[1], 90)
    # beyond max_pixels usable pixels the equations are not held: pixel centres instead
    bounded = gather_observations(caster, views, max_pixels=100)
    centres = gather_observations(caster, views, subpixel_samples=1)
    np.testing.assert_array_equal(bounded.face, centres.face)
    np.testing.assert_array_equal(bounded.rgb, centres.rgb)


def test_one_sub_pixel_ray_is_the_pixel_centre_ray_and_more_tile_the_pixel():
    cam = Camera(look_at([0.3, 0.8, 3.5], [0, 0, 0]), 48.0, 52.0, 20.5, 14.0, 40, 30)
    pixels = np.array([0, 7, 39, 40, 555, 1199])
    np.testing.assert_allclose(cam.subpixel_directions(pixels, 1), cam.pixel_directions()[:, pixels], atol=1e-15)
    fine = Camera(cam.c2w, 3 * cam.fx, 3 * cam.fy, 3 * cam.cx, 3 * cam.cy, 120, 90)   # 3x the resolution
    row, col = np.divmod(pixels, 40)
    sub = (3 * row[:, None, None] + np.arange(3)[None, :, None]) * 120 + 3 * col[:, None, None] + np.arange(3)
    np.testing.assert_allclose(cam.subpixel_directions(pixels, 3), fine.pixel_directions()[:, sub.ravel()],
                               atol=1e-15)
    caster = RayCaster(sphere(2))
    np.testing.assert_array_equal(caster.subpixel_faces(cam, 1, np.arange(1200)).ravel(),
                                  caster.face_id_buffer(cam).ravel())


def test_a_faces_radiance_error_grows_as_its_share_of_the_pixels_shrinks():
    """Pixels with noise of 0.01, each holding one face at a share of 1, 1/2 or 1/8: each face's
    radiance error is the pixels' noise level over the root of its summed squared shares (a face
    an eighth of one pixel: 8 times the noise); a face in no pixel has an infinite one."""
    from estimator.pipeline.footprints import radiance_error

    rng = np.random.default_rng(3)
    pixels = 4000
    share = np.array([1.0, 0.5, 0.125, 0.0])
    rows = np.arange(pixels)
    # each pixel covered by one face alone, in turn: the first three faces, 1/3 of the pixels each
    owner = rows % 3
    shares = sp.csr_matrix((share[owner], (rows, owner)), shape=(pixels, 4))
    rgb = rng.normal(0.0, 0.01, (pixels, 3))
    error = radiance_error(Footprints(shares, rgb, np.zeros(pixels, np.int64)), np.zeros((4, 3)))
    count = pixels / 3
    expected = 0.01 / np.sqrt(count * share[:3] ** 2)
    np.testing.assert_allclose(error[:3, 0], expected, rtol=0.1)
    assert np.all(np.isinf(error[3]))


def test_an_unmixed_radiance_error_enters_every_row_of_the_face():
    """One row per view x = 1 for a face: the albedo's variance is sigma^2 / n from the rows plus
    s^2 from the one radiance every row holds (s the radiance error), so its precision saturates
    at 1 / s^2 however many views see it."""
    from estimator.diagnostics.trust import _precision

    n = np.array([1, 4, 100])
    face = np.repeat(np.arange(3), n)
    rows = np.ones((len(face), 3))
    sigma = np.full(3, 0.01)
    s = np.full((3, 3), 0.05)
    precision = _precision(face, 3, rows, np.zeros(len(face), bool), sigma, s)
    np.testing.assert_allclose(precision[:, 0], 1.0 / (0.01 ** 2 / n + 0.05 ** 2), rtol=1e-12)
    np.testing.assert_allclose(_precision(face, 3, rows, np.zeros(len(face), bool), sigma)[:, 0], n / 0.01 ** 2)
