"""An unmodelled reflection is told from a fault of one view by the mirror direction:
``estimator.diagnostics.trust.reflected_rows`` on hand-built observations."""
from types import SimpleNamespace

import numpy as np

from estimator.diagnostics.trust import reflected_rows


def _prep(mirror: np.ndarray, view: np.ndarray) -> SimpleNamespace:
    """Observations of faces with normal +Z whose mirror directions are ``mirror`` (N, 3)."""
    mirror = mirror / np.linalg.norm(mirror, axis=1, keepdims=True)
    normal = np.array([0.0, 0.0, 1.0])
    view_dir = 2.0 * (mirror @ normal)[:, None] * normal - mirror   # the mirror of a mirror
    n = len(mirror)
    obs = SimpleNamespace(face=np.arange(n), view=view, view_dir=view_dir, num_views=int(view.max()) + 1)
    return SimpleNamespace(obs=obs, data=SimpleNamespace(mesh=SimpleNamespace(face_normals=np.tile(normal, (n, 1)))))


def _tilt(degrees: float, azimuth: float = 0.0) -> np.ndarray:
    t, a = np.radians(degrees), np.radians(azimuth)
    return np.array([np.sin(t) * np.cos(a), np.sin(t) * np.sin(a), np.cos(t)])


def test_a_highlight_seen_from_two_views_is_a_reflection_and_a_lone_one_is_not():
    # rows 0/1: one highlight in views 0 and 1, 1 degree apart in mirror direction
    # rows 2/3: a bright row of view 0 whose nearest other-view row (2 degrees away) fits
    # rows 4/5: a bright row of view 0 whose nearest other-view row is an outlier, but darker
    # rows 6/7: a dark row (an occluder) whose neighbour is dark too: a missing highlight's shape
    mirror = np.array([_tilt(30, 0), _tilt(31, 0), _tilt(30, 120), _tilt(32, 120), _tilt(30, 240),
                       _tilt(31, 240), _tilt(60, 60), _tilt(61, 60)])
    view = np.array([0, 1, 0, 1, 0, 1, 0, 1])
    relative = np.array([0.5, 0.4, 0.5, 0.01, 0.5, 0.4, 0.3, 0.3])
    residual = np.array([1, 1, 1, 1, 1, -1, -1, -1])[:, None] * relative[:, None] * np.ones(3)
    rows = np.array([0, 2, 4, 6])
    got = reflected_rows(_prep(mirror, view), np.full(8, -1), residual, relative, np.ones(8, bool), rows, 0.1)
    np.testing.assert_array_equal(got, [True, False, False, True])


def test_the_neighbour_must_share_the_face_group():
    """On an object that mixes materials, a matte face's fit says nothing of a glossy face's
    highlight, nor a glossy face's highlight of a matte face's glare."""
    mirror = np.array([_tilt(30, 0), _tilt(31, 0), _tilt(34, 0), _tilt(45, 0)])
    view = np.array([0, 1, 1, 0])
    relative = np.array([0.5, 0.5, 0.01, 0.01])
    residual = relative[:, None] * np.ones(3)
    estimated = np.ones(4, bool)
    prep = _prep(mirror, view)
    # one group for all: row 1 (another view, 1 degree) explains row 0
    assert reflected_rows(prep, np.array([0, 0, 0, 0]), residual, relative, estimated, np.array([0]), 0.1)[0]
    # row 1 in another group: row 0's nearest same-group row of another view is row 2, which fits
    assert not reflected_rows(prep, np.array([0, 1, 0, 1]), residual, relative, estimated, np.array([0]), 0.1)[0]
    # single-face labels (a per-face method) group nothing: any face votes
    assert reflected_rows(prep, np.arange(4), residual, relative, estimated, np.array([0]), 0.1)[0]


def test_no_other_view_explains_nothing():
    mirror = np.array([_tilt(30, 0), _tilt(31, 0)])
    relative = np.array([0.5, 0.5])
    residual = relative[:, None] * np.ones(3)
    prep = _prep(mirror, np.array([0, 0]))
    prep.obs.num_views = 2
    labels, estimated = np.full(2, -1), np.ones(2, bool)
    assert not reflected_rows(prep, labels, residual, relative, estimated, np.array([0]), 0.1)[0]
    assert reflected_rows(prep, labels, residual, relative, estimated, np.array([], int), 0.1).shape == (0,)


def _shadow_prep(rgb: np.ndarray, face: np.ndarray, along_mirror: bool = True) -> SimpleNamespace:
    """Rows ``rgb`` (N, 3) of three faces with normal +Z, each seen with mirror direction r
    tilted 60 degrees towards +X: face 0 open to its whole upper hemisphere (its directions
    below the plane, within 90 degrees of r, are not shadows), face 1 hidden by the object
    from the directions above its plane within 30 degrees of +X (within 90 degrees of r),
    face 2 from those within 30 degrees of -X (all over 90 degrees from r); diffuse shading
    0.5, unshadowed reflection 0.8 per channel."""
    from estimator.rays.visibility import Visibility, sphere_sampling

    sampling = sphere_sampling(162)
    d = sampling.directions
    up = d[:, 2] > 0
    near_x, near_minus_x = d[:, 0] > np.cos(np.radians(30)), -d[:, 0] > np.cos(np.radians(30))
    bits = np.packbits(np.stack([up, up & ~near_x, up & ~near_minus_x]), axis=1)
    mirror = np.array([np.sin(np.radians(60)), 0.0, np.cos(np.radians(60))])
    n = len(face)
    return SimpleNamespace(
        obs=SimpleNamespace(face=face, rgb=rgb), sampling=sampling, visibility=Visibility(bits, len(d)),
        data=SimpleNamespace(mesh=SimpleNamespace(face_normals=np.tile([0.0, 0.0, 1.0], (3, 1)))),
        model=SimpleNamespace(shadow_along_mirror=along_mirror,
                              unshadowed_specular_shading=lambda mirror, light: np.full((len(mirror), 3), 0.8)),
        row_mirrors=lambda rows: np.tile(mirror, (len(rows), 1))), np.full((n, 3), 0.5)


def test_a_gross_error_between_the_shadow_bounds_of_a_shadowed_face_is_not_a_fault():
    """Albedo 0.4, specular 0.5: the diffuse term alone is 0.2, with the unshadowed reflection
    0.6. On the face the object shadows within 90 degrees of its mirror direction, a row at
    either bound or between them is explained; glare above the reflection and a black occluder
    (0, further below the diffuse term than 20 % of the level) are not. On the face open to its
    hemisphere, and on the face shadowed only beyond 90 degrees of r, nothing is. Nor under a
    model that integrates the visibility over its lobe."""
    from estimator.diagnostics.trust import shadow_edge_rows

    values = [0.6, 0.2, 0.4, 1.2, 0.0, 0.6, 0.2, 0.6, 0.2, 0.6]
    rgb = np.array(values)[:, None] * np.ones(3)
    face = np.array([1, 1, 1, 1, 1, 0, 0, 2, 2, 1])
    est = SimpleNamespace(diffuse=np.full((3, 3), 0.4), specular=np.full((3, 3), 0.5), light=None)
    prep, shade = _shadow_prep(rgb, face)
    got = shadow_edge_rows(prep, est, np.arange(9), shade)
    assert got.tolist() == [True, True, True, False, False, False, False, False, False]
    prep, shade = _shadow_prep(rgb, face, along_mirror=False)
    assert not shadow_edge_rows(prep, est, np.arange(9), shade).any()
    assert shadow_edge_rows(prep, est, np.array([], dtype=np.int64), shade).shape == (0,)
