"""Bad inputs give clear errors; observations are gathered exactly."""
import numpy as np
import pytest

from estimator import estimate
from estimator.config import EstimatorConfig
from estimator.core.camera import Camera, look_at
from estimator.core.data import MultiViewData, TriangleMesh, View
from estimator.core.errors import InputError
from estimator.pipeline.observations import Observations, gather_observations
from estimator.rays.raycast import RayCaster

from .meshes import sphere

CAM = Camera.from_fov(look_at([0, 0, 4], [0, 0, 0]), 30, 16, 12)


def test_mesh_errors():
    with pytest.raises(ValueError, match="no faces"):
        TriangleMesh(np.zeros((3, 3)), np.zeros((0, 3), int))
    with pytest.raises(ValueError, match="triangles"):
        TriangleMesh(np.zeros((4, 3)), np.array([[0, 1, 2, 3]]))
    with pytest.raises(ValueError, match="indices"):
        TriangleMesh(np.zeros((3, 3)), np.array([[0, 1, 5]]))
    with pytest.raises(ValueError, match="NaN"):
        TriangleMesh(np.full((3, 3), np.nan), np.array([[0, 1, 2]]))
    line = np.array([[10.0, 10.0, 10.0], [10.3, 10.7, 10.1], [10.9, 12.1, 10.3]], np.float32).astype(float)
    with pytest.raises(ValueError, match="no face with non-zero area"):   # collinear to float32 rounding
        TriangleMesh(line, np.array([[0, 1, 2]]))


def test_a_mesh_computes_its_normals_and_centroids_once_read_only():
    """Every view's rows and rays start at the faces' centroids and normals: computed once per
    mesh and shared, so a caller cannot change them under the others."""
    mesh = sphere(1)
    corners = mesh.vertices[mesh.faces]
    np.testing.assert_allclose(mesh.centroids, corners.mean(axis=1), atol=1e-15)
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    np.testing.assert_allclose(mesh.face_normals, n / np.linalg.norm(n, axis=1, keepdims=True), atol=1e-15)
    assert mesh.centroids is mesh.centroids and mesh.face_normals is mesh.face_normals
    for array in (mesh.centroids, mesh.face_normals):
        with pytest.raises(ValueError, match="read-only"):
            array[0, 0] = 1.0


def test_view_errors():
    with pytest.raises(ValueError, match="intrinsics say 16x12"):
        View("a", CAM, np.zeros((10, 16, 3)))
    bad = np.zeros((12, 16, 3))
    bad[1, 1, 1] = np.inf
    with pytest.raises(ValueError, match="NaN or Inf"):
        View("a", CAM, bad)
    with pytest.raises(ValueError, match="no frames"):
        MultiViewData(sphere(1), [])


def test_cameras_that_see_nothing_are_refused():
    away = Camera.from_fov(look_at([0, 0, 4], [0, 0, 8]), 30, 16, 12)
    data = MultiViewData(sphere(1), [View("away", away, np.zeros((12, 16, 3)))])
    with pytest.raises(ValueError, match="no camera sees any face"):
        estimate(data, "median-color", EstimatorConfig(sh_order=2, directions=50))
    good = View("good", CAM, np.zeros((12, 16, 3)))
    data = MultiViewData(sphere(1), [good, View("away", away, np.zeros((12, 16, 3)))])
    with pytest.raises(ValueError, match="1 camera.s. see none of the mesh: away"):
        estimate(data, "median-color", EstimatorConfig(sh_order=2, directions=50))


def test_a_view_whose_pixels_on_the_mesh_are_all_negative_is_named():
    """A sign or black-level error, not a pose error: the message says so and names the view."""
    good = View("good", CAM, np.full((12, 16, 3), 0.5))
    flipped = View("flipped", CAM, np.full((12, 16, 3), -0.5))
    data = MultiViewData(sphere(1), [good, flipped])
    with pytest.raises(ValueError, match=r"1 view.s. show the mesh but every pixel on it has a channel below zero "
                                         r"\(or is black\): flipped"):
        estimate(data, "median-color", EstimatorConfig(sh_order=2, directions=50))
    # a few pixels at exactly zero among the negative ones: still a sign error, not a pose error
    rgb = np.full((12, 16, 3), -0.5)
    rgb[6, 8] = 0.0
    data = MultiViewData(sphere(1), [good, View("flipped", CAM, rgb)])
    with pytest.raises(ValueError, match=r"every pixel on it has a channel below zero \(or is black\): flipped"):
        estimate(data, "median-color", EstimatorConfig(sh_order=2, directions=50))
    # a black view (its side unlit) with one pixel a little below zero is no sign error
    black = np.zeros((12, 16, 3))
    black[6, 8] = -1e-3
    estimate(MultiViewData(sphere(1), [good, View("unlit", CAM, black)]), "median-color",
             EstimatorConfig(sh_order=2, directions=50))


def test_cameras_inside_the_mesh_name_its_scale_beside_the_winding():
    """A mesh in other units (here 100x) around the cameras: every face is seen from behind, as
    with a reversed winding; the message names the scale too (reversing the winding there
    would silently estimate garbage). Cameras outside the bounds hear of the winding alone."""
    mesh = sphere(1)
    huge = TriangleMesh(mesh.vertices * 100.0, mesh.faces)
    data = MultiViewData(huge, [View("v", CAM, np.ones((12, 16, 3)))])
    with pytest.raises(ValueError, match="reverse the winding.*1 of the 1 cameras lie inside the mesh's bounding "
                                         "box.*different units"):
        estimate(data, "median-color", EstimatorConfig(sh_order=2, directions=50))
    inward = TriangleMesh(mesh.vertices, mesh.faces[:, ::-1])
    with pytest.raises(ValueError, match=r"mesh.invert\(\)$"):
        estimate(MultiViewData(inward, [View("v", CAM, np.ones((12, 16, 3)))]), "median-color",
                 EstimatorConfig(sh_order=2, directions=50))


def test_faces_of_zero_area_and_repeated_faces_are_named_in_warnings():
    mesh = sphere(1)
    faces = np.vstack([mesh.faces, mesh.faces[:2], [[0, 0, 1]]])   # two repeats, then a face of zero area
    odd = TriangleMesh(mesh.vertices, faces)
    flat, repeated = odd.degenerate_faces()
    assert np.flatnonzero(flat).tolist() == [len(faces) - 1]
    assert np.flatnonzero(repeated).tolist() == [len(mesh.faces), len(mesh.faces) + 1]
    est = estimate(MultiViewData(odd, [View("v", CAM, np.ones((12, 16, 3)))]), "median-color",
                   EstimatorConfig(sh_order=2, directions=50))
    assert any(f"1 face(s) of the mesh have zero area or corners in a line, to the rounding of their coordinates "
               f"(first: {len(faces) - 1})" in w for w in est.info["warnings"])
    assert any("2 face(s) of the mesh repeat" in w for w in est.info["warnings"])
    clean = estimate(MultiViewData(mesh, [View("v", CAM, np.ones((12, 16, 3)))]), "median-color",
                     EstimatorConfig(sh_order=2, directions=50))
    assert not any("of the mesh" in w for w in clean.info["warnings"])


def test_faces_with_corners_in_a_line_to_float32_rounding_have_no_normal():
    """Three corners in a line, written in float32, leave an area of the coordinates' rounding
    and a normal of noise: the face is flat (never observed), as a face of zero area is; a thin
    but real sliver (height 1e-4 of its length) keeps its normal."""
    base = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    line = np.array([[10.0, 10.0, 10.0], [10.3, 10.7, 10.1], [10.9, 12.1, 10.3]], np.float32).astype(float)
    sliver = np.array([[0, 0, 2], [1, 0, 2], [0.5, 1e-4, 2]], float)
    mesh = TriangleMesh(np.vstack([base, line, sliver]), np.arange(9).reshape(3, 3))
    assert np.linalg.norm(np.cross(line[1] - line[0], line[2] - line[0])) > 0   # not exactly zero
    assert mesh.flat.tolist() == [False, True, False]
    assert mesh.face_normals[1].tolist() == [0.0, 0.0, 0.0]
    np.testing.assert_allclose(mesh.face_normals[2], [0, 0, 1])
    assert mesh.degenerate_faces()[0].tolist() == [False, True, False]


def test_an_unwelded_mesh_has_the_welded_one_s_neighbours_and_repeats():
    """Every face with its own three vertices (STL, many exports): faces are neighbours where
    their corners share positions, so the adjacency (and everything the edge fit and the
    segmentation build on it) equals the welded mesh's; a face repeated through copies of an
    earlier face's vertices is a repeat."""
    mesh = sphere(1)
    unwelded = TriangleMesh(mesh.vertices[mesh.faces].reshape(-1, 3), np.arange(3 * mesh.num_faces).reshape(-1, 3))
    assert len(unwelded.vertices) == 3 * mesh.num_faces
    np.testing.assert_array_equal(unwelded.face_adjacency, mesh.face_adjacency)
    copied = TriangleMesh(np.vstack([unwelded.vertices, mesh.vertices[mesh.faces[5]]]),
                          np.vstack([unwelded.faces, len(unwelded.vertices) + np.arange(3)]))
    assert np.flatnonzero(copied.degenerate_faces()[1]).tolist() == [mesh.num_faces]


def test_a_mesh_wound_inwards_is_named():
    """Normals pointing inwards: every visible face is seen from behind, and the error says
    the winding is reversed rather than blaming the poses or min_cos_view."""
    mesh = sphere(1)
    inward = TriangleMesh(mesh.vertices, mesh.faces[:, ::-1])
    data = MultiViewData(inward, [View("v", CAM, np.ones((12, 16, 3)))])
    with pytest.raises(ValueError, match="wound the other way"):
        estimate(data, "median-color", EstimatorConfig(sh_order=2, directions=50))
    estimate(MultiViewData(mesh, [View("v", CAM, np.ones((12, 16, 3)))]), "median-color",
             EstimatorConfig(sh_order=2, directions=50))                       # outward: accepted


def test_a_fully_transparent_view_is_named():
    clear = View("clear", CAM, np.ones((12, 16, 3)), alpha=np.zeros((12, 16)))
    data = MultiViewData(sphere(1), [View("good", CAM, np.ones((12, 16, 3))), clear])
    with pytest.raises(ValueError, match="1 view.s. are fully transparent .* clear"):
        estimate(data, "median-color", EstimatorConfig(sh_order=2, directions=50))


def test_observations_are_per_face_means_of_pure_pixels():
    mesh = sphere(1)
    caster = RayCaster(mesh)
    cam = Camera.from_fov(look_at([0, 0, 4], [0, 0, 0]), 30, 64, 64)
    ids = caster.face_id_buffer(cam)
    pure = caster.face_id_buffers([cam], pure=True)[0]
    assert np.all((pure == ids) | (pure == -1)) and (pure >= 0).sum() < (ids >= 0).sum()
    image = np.where(ids[..., None] >= 0, (ids[..., None] + 1.0) * [1.0, 2.0, 3.0], 0.0)  # face-constant colour
    obs = gather_observations(caster, [View("v", cam, image)])
    # the faces no pure pixel covers (at the silhouette) are unmixed from the pixels they share (thin)
    pure_rows = ~obs.thin[obs.face] if obs.thin is not None else np.ones(len(obs.face), bool)
    assert np.array_equal(np.unique(obs.face[pure_rows]), np.unique(pure[pure >= 0]))
    np.testing.assert_allclose(obs.rgb[pure_rows], (obs.face[pure_rows, None] + 1.0) * [1.0, 2.0, 3.0])
    np.testing.assert_allclose(np.linalg.norm(obs.view_dir, axis=1), 1.0)


def _means(ids: np.ndarray, image: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(K, 3) mean of ``image`` over the pixels of each of ``faces`` in the face-ID buffer ``ids``."""
    hit = ids.ravel() >= 0
    flat, rgb = ids.ravel()[hit], image.reshape(-1, 3)[hit]
    counts = np.bincount(flat)[faces]
    sums = np.stack([np.bincount(flat, rgb[:, c])[faces] for c in range(3)], axis=1)
    return sums / counts[:, None]


@pytest.mark.parametrize("size, dense", [(40, True), (160, False)])
def test_faces_smaller_than_a_pixel_are_observed_through_their_pixel_centres(size, dense):
    """Where pure pixels resolve under half of the faces pixel centres hit (a mesh denser than
    its photos), a face that covers no whole pixel is observed, with one sub-pixel sample
    (``subpixel_samples=1``), through its pixel centres; a
    face that covers one keeps the mean of its pure pixels alone. Where they resolve most
    faces, the rest stay unobserved."""
    mesh = sphere(3)                                                 # 1,280 faces
    caster = RayCaster(mesh)
    cam = Camera.from_fov(look_at([0, 0, 4], [0, 0, 0]), 30, size, size)
    ids = caster.face_id_buffer(cam)
    pure = caster.face_id_buffers([cam], pure=True)[0]
    hit, covered = np.unique(ids[ids >= 0]), np.unique(pure[pure >= 0])
    assert (2 * len(covered) < len(hit)) == dense and len(covered) < len(hit)
    image = np.random.default_rng(0).random((size, size, 3)).astype(np.float32)   # as a View holds it
    obs = gather_observations(caster, [View("v", cam, image)], subpixel_samples=1)
    np.testing.assert_array_equal(obs.face, hit if dense else covered)
    through_pure = np.isin(obs.face, covered)
    np.testing.assert_allclose(obs.rgb[through_pure], _means(pure, image, obs.face[through_pure]), rtol=1e-12)
    np.testing.assert_allclose(obs.rgb[~through_pure], _means(ids, image, obs.face[~through_pure]), rtol=1e-12)
    if dense:
        unresolved = np.setdiff1d(hit, covered)
        np.testing.assert_array_equal(np.nonzero(obs.unresolved)[0], unresolved)
        # the mean pixel-centre count of an unresolved face's row
        assert obs.footprint_pixels == pytest.approx(np.isin(ids, unresolved).sum() / len(unresolved), rel=1e-12)
    else:
        assert obs.unresolved is None and obs.footprint_pixels is None
    centres = gather_observations(caster, [View("v", cam, image)], pure_pixels=False)
    np.testing.assert_allclose(centres.rgb, _means(ids, image, hit), rtol=1e-12)
    assert centres.unresolved is None


def test_a_far_view_with_no_face_whole_in_a_pixel_gives_no_row_and_is_named_not_refused():
    """A near view resolves the faces (pure pixels); a far one shows the mesh, but no face covers
    one of its pixels whole: it gives no row and is named in ``rowless_views`` and a warning
    (it was refused as a camera that sees none of the mesh); so is one whose faces each cover
    fewer than ``min_pixels`` of its pixels, with that setting named. A camera that sees
    nothing is still refused."""
    mesh = sphere(3)                                                 # 1,280 faces
    caster = RayCaster(mesh)
    near = [Camera.from_fov(look_at(eye, [0, 0, 0]), 30, 160, 160) for eye in ([0, 0, 4], [4, 0, 1], [0, 4, 1])]
    far = Camera.from_fov(look_at([0, 0, 16], [0, 0, 0]), 30, 24, 24)
    assert not np.any(caster.face_id_buffers([far], pure=True)[0] >= 0)
    assert np.any(caster.face_id_buffer(far) >= 0)
    views = [View(f"near{i}", cam, np.full((160, 160, 3), 0.5)) for i, cam in enumerate(near)]
    views.append(View("far", far, np.full((24, 24, 3), 0.5)))
    obs = gather_observations(caster, views)
    np.testing.assert_array_equal(obs.rowless_views, [3])
    assert obs.unresolved is None and 3 not in obs.view
    est = estimate(MultiViewData(mesh, views), "median-color", EstimatorConfig(sh_order=2, directions=50,
                                                                               view_gains=True))
    assert est.info["rowless_views"] == ["far"]
    assert est.info["view_gains"]["far"] is None and len(est.info["view_gains"]["near0"]) == 3
    assert any("no face covers a pixel of theirs whole" in w and "(far;" in w for w in est.info["warnings"])
    mid = Camera.from_fov(look_at([0, 0, 6], [0, 0, 0]), 30, 64, 64)
    assert np.any(caster.face_id_buffers([mid], pure=True)[0] >= 0)
    est = estimate(MultiViewData(mesh, views[:3] + [View("mid", mid, np.full((64, 64, 3), 0.5))]),
                   "median-color", EstimatorConfig(sh_order=2, directions=50, min_pixels=9))
    assert est.info["rowless_views"] == ["mid"]     # faces whole in its pixels, but in fewer than 9 each
    assert any("min_pixels=9 of their pixels whole" in w and "min_pixels too high" in w for w in est.info["warnings"])
    away = Camera.from_fov(look_at([0, 0, 4], [0, 0, 8]), 30, 24, 24)     # looks away from the mesh
    with pytest.raises(InputError, match="1 camera.*see none of the mesh: away"):
        gather_observations(caster, views[:3] + [View("away", away, np.full((24, 24, 3), 0.5))])


def test_an_estimate_counts_the_faces_observed_through_pixel_centres():
    """Every face a pixel centre hits in a whole object pixel (alpha 1, as the sub-pixel rays
    measure it) and no pure pixel resolves is counted, and estimated."""
    mesh = sphere(3)
    caster = RayCaster(mesh)
    cams = [Camera.from_fov(look_at(eye, [0, 0, 0]), 30, 40, 40) for eye in ([0, 0, 4], [0, 4, 0.1])]
    hit, covered = np.zeros(mesh.num_faces, bool), np.zeros(mesh.num_faces, bool)
    views = []
    buffers = zip(cams, caster.face_id_buffers(cams), caster.face_id_buffers(cams, pure=True))
    for i, (cam, ids, pure) in enumerate(buffers):
        alpha = np.mean(caster.subpixel_faces(cam, 4, np.arange(40 * 40)) >= 0, axis=1).reshape(40, 40)
        hit[ids[(ids >= 0) & (alpha == 1)]] = True
        covered[pure[pure >= 0]] = True
        views.append(View(f"v{i}", cam, np.full((40, 40, 3), 0.5), alpha=alpha))
    est = estimate(MultiViewData(mesh, views), "median-color", EstimatorConfig(sh_order=2, directions=50))
    assert est.info["unresolved_faces"] >= (hit & ~covered).sum() > 0
    assert np.all(est.observed[hit])


def test_a_view_without_a_usable_pixel_on_a_dense_mesh_is_named_not_fatal():
    """A mesh denser than its photos (faces observed through the pixels they cover, sub-pixel
    rays per usable pixel) with one view negative everywhere: an InputError that names it, not
    a process aborted by Dr.Jit (a launch of no sub-pixel rays for that view's no pixels). No
    pixel at all asks for no sub-pixel ray."""
    mesh = sphere(5)   # 20,480 faces at 24 x 24 pixels
    caster = RayCaster(mesh)
    cams = [Camera.from_fov(look_at(eye, [0, 0, 0]), 30, 24, 24) for eye in ([0, 0, 4], [0, 4, 0.1], [4, 0, 0])]
    assert caster.subpixel_faces(cams[0], 4, np.zeros(0, dtype=np.int64)).shape == (0, 16)
    rgb = np.full((24, 24, 3), 0.5)
    views = [View("bad", cams[0], -rgb, alpha=np.ones((24, 24)))]
    views += [View(f"v{i}", cam, rgb, alpha=np.ones((24, 24))) for i, cam in enumerate(cams[1:])]
    with pytest.raises(InputError, match="bad"):
        estimate(MultiViewData(mesh, views), "median-color", EstimatorConfig(sh_order=2, directions=50))


def test_a_transparent_view_is_refused_before_the_poses_are_refined(monkeypatch):
    """The pose refinement's held-out estimates would trace and solve every view first: a view
    whose alpha is 0 everywhere is named before any of that."""
    from estimator.pipeline import pose

    def refine(*args, **kwargs):
        raise AssertionError("the poses were refined before the transparent view was named")

    monkeypatch.setattr(pose, "refine_poses", refine)
    mesh = sphere(1)
    cams = [Camera.from_fov(look_at(eye, [0, 0, 0]), 30, 24, 24) for eye in ([0, 0, 4], [0, 4, 0.1], [4, 0, 0])]
    views = [View(f"v{i}", cam, np.full((24, 24, 3), 0.5), alpha=np.full((24, 24), float(i > 0)))
             for i, cam in enumerate(cams)]
    with pytest.raises(InputError, match="fully transparent.*v0"):
        estimate(MultiViewData(mesh, views), "median-color", EstimatorConfig(sh_order=2, directions=50, pose_rounds=2))


def test_a_face_id_buffer_is_the_first_hit_of_each_pixel_ray():
    """The buffers' rays, made per axis for a batch of cameras, are the cameras' own pixel rays."""
    mesh = sphere(2)
    cams = [Camera(look_at([0.3, 0.8, 3.5], [0, 0, 0]), 48.0, 52.0, 20.5, 14.0, 40, 30),
            Camera.from_fov(look_at([3, 1, 2], [0, 0, 0]), 40, 24, 36)]
    caster = RayCaster(mesh)
    for cam, buffer in zip(cams, caster.face_id_buffers(cams)):
        assert buffer.shape == (cam.height, cam.width) and (buffer >= 0).any() and (buffer < 0).any()
        np.testing.assert_array_equal(buffer.ravel(), caster.first_hit_faces(*cam.pixel_rays()))


def test_face_id_buffers_are_traced_once_per_camera(monkeypatch):
    """The pose check, the pose refinement's estimates and the observations trace the same views:
    a later call traces only what is new (the corner rays; a moved camera) and gives what a
    fresh caster gives."""
    mesh = sphere(1)
    cams = [Camera.from_fov(look_at(eye, [0, 0, 0]), 30, 40, 32) for eye in ([0, 0, 4], [3, 1, 2])]
    fresh_pure = RayCaster(mesh).face_id_buffers(cams, pure=True, max_rays=1500)
    caster = RayCaster(mesh)
    traced = []
    original = caster._first_hits

    def counted(ray):
        hits = original(ray)
        traced.append(len(hits))
        return hits

    monkeypatch.setattr(caster, "_first_hits", counted)
    centres = caster.face_id_buffers(cams, max_rays=1500)
    assert sum(traced) == 2 * 40 * 32 and not centres[0].flags.writeable
    traced.clear()
    pure = caster.face_id_buffers(cams, pure=True, max_rays=1500)
    assert sum(traced) == 2 * 41 * 33                                # the corners alone
    for a, b in zip(pure, fresh_pure):
        np.testing.assert_array_equal(a, b)
    moved = Camera.from_fov(look_at([0, 0.5, 4], [0, 0, 0]), 30, 40, 32)
    traced.clear()
    again = caster.face_id_buffers([cams[0], moved], max_rays=1500)
    assert sum(traced) == 40 * 32 and again[0] is centres[0]         # the moved camera alone
    np.testing.assert_array_equal(again[1], RayCaster(mesh).face_id_buffer(moved))
    traced.clear()
    later = caster.face_id_buffers(cams + [moved], pure=True, max_rays=1500)
    assert sum(traced) == 41 * 33 and later[1] is pure[1]            # the cameras of every earlier call are kept


def test_face_id_buffers_are_kept_within_their_budget(monkeypatch):
    """Beyond BUFFER_CACHE_BYTES the least recently used buffers are dropped (and traced again)."""
    from estimator.rays import raycast

    monkeypatch.setattr(raycast, "BUFFER_CACHE_BYTES", 3 * 40 * 32 * 4)   # three int32 buffers
    caster = RayCaster(sphere(1))
    cams = [Camera.from_fov(look_at(eye, [0, 0, 0]), 30, 40, 32) for eye in ([0, 0, 4], [3, 1, 2], [0, 4, 1],
                                                                                [-3, 0, 2])]
    first = caster.face_id_buffers(cams)                              # four: the first is dropped
    assert sum(b.nbytes for b in caster._buffers.values()) <= raycast.BUFFER_CACHE_BYTES
    assert caster.face_id_buffers(cams[3:])[0] is first[3]
    again = caster.face_id_buffers(cams[:1])[0]
    assert again is not first[0]
    np.testing.assert_array_equal(again, first[0])


def test_median_colour_matches_numpy():
    rng = np.random.default_rng(0)
    face = rng.integers(0, 7, 60)
    rgb = rng.random((60, 3))
    obs = Observations(face, rgb, np.zeros((60, 3)), 9, 1)
    med = obs.median_color()
    for f in range(9):
        if (face == f).any():
            np.testing.assert_allclose(med[f], np.median(rgb[face == f], axis=0))
        else:
            assert np.all(np.isnan(med[f]))


def test_a_mesh_beyond_float32_reach_is_refused_before_tracing():
    """A mesh scaled by 1e30 segfaulted once in 49 runs inside the ray tracer."""
    from estimator import InputError

    mesh = TriangleMesh(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]) * 1e30, np.array([[0, 1, 2]]))
    with pytest.raises(InputError, match="rescale the mesh"):
        RayCaster(mesh)


def test_a_view_scaled_beyond_any_dynamic_range_is_named():
    """One view multiplied by 1e38 gave albedos of 6e49 with exit 0 (or sank the estimate)."""
    from estimator import InputError

    from .micro import micro_config, micro_scene

    data, _ = micro_scene()
    views = [View(v.name, v.camera, v.rgb * (1e38 if k == 3 else 1.0), v.alpha) for k, v in enumerate(data.views)]
    with pytest.raises(InputError, match=r"view view3 is exposed 1\.\d+e\+38 x the median view.s level"):
        estimate(MultiViewData(data.mesh, views), "bilinear-clustered", micro_config())


def test_a_caster_of_another_mesh_is_refused():
    data = MultiViewData(sphere(1), [View("v", CAM, np.ones((12, 16, 3)))])
    with pytest.raises(ValueError, match="caster was built for another mesh"):
        estimate(data, "median-color", EstimatorConfig(sh_order=2, directions=50), caster=RayCaster(sphere(2)))


def test_a_view_that_shows_the_mesh_black_gives_no_row_and_is_named():
    """A view whose every pixel on the mesh is zero (a failed capture) gives no row, so its zeros
    do not pull the faces' colours down, and is named in ``black_views`` and a warning; the
    other views' rows are those they give alone. Every view black is refused."""
    mesh = sphere(3)
    caster = RayCaster(mesh)
    cams = [Camera.from_fov(look_at(eye, [0, 0, 0]), 30, 48, 48) for eye in ([0, 0, 4], [4, 0, 1], [0, 4, 1])]
    lit = [View(f"v{i}", cam, np.full((48, 48, 3), 0.5)) for i, cam in enumerate(cams)]
    black = View("black", Camera.from_fov(look_at([0, 0, -4], [0, 0, 0]), 30, 48, 48), np.zeros((48, 48, 3)))
    obs = gather_observations(caster, lit + [black])
    alone = gather_observations(caster, lit)
    np.testing.assert_array_equal(obs.black_views, [3])
    assert 3 not in obs.view and len(obs.rowless_views) == 0
    np.testing.assert_array_equal(obs.face, alone.face)
    est = estimate(MultiViewData(mesh, lit + [black]), "median-color", EstimatorConfig(sh_order=2, directions=50))
    assert est.info["black_views"] == ["black"]
    assert any("1 view(s) show the mesh black" in w and "(black;" in w for w in est.info["warnings"])
    with pytest.raises(InputError, match="every view shows the mesh black"):
        gather_observations(caster, [black, View("black2", cams[0], np.zeros((48, 48, 3)))])


def test_a_channel_no_pixel_records_is_named_where_the_light_is_fitted():
    """A light (or camera) without green: the default, which fits the light to every channel,
    names the channel; a method that fits no light still gives a green albedo of 0."""
    image = np.full((12, 16, 3), 0.5)
    image[..., 1] = 0.0
    data = MultiViewData(sphere(1), [View("v", CAM, image)])
    with pytest.raises(InputError, match="the green channel is zero or negative in every observation"):
        estimate(data, "retinex-segmented", EstimatorConfig(sh_order=2, directions=50))
    est = estimate(data, "median-color", EstimatorConfig(sh_order=2, directions=50))
    assert est.observed.any() and np.all(est.diffuse[est.observed, 1] == 0)


def test_faces_wound_against_their_neighbours_are_counted_and_named_in_a_warning():
    """A few faces wound the other way run their shared edges in the same direction as their
    neighbours: each such edge is a conflict (three for a lone face, four for a flipped pair),
    counted in ``winding_conflicts`` and a warning; a consistent mesh has none."""
    mesh = sphere(2)
    assert not mesh.winding_conflicts().any()
    faces = mesh.faces.copy()
    faces[[3, 50, 51]] = faces[[3, 50, 51]][:, ::-1]
    flipped = TriangleMesh(mesh.vertices, faces)
    pair = flipped.face_adjacency
    adjacent = {tuple(p) for p in pair.tolist()}
    assert (50, 51) in adjacent and not ({3} & {50, 51})
    conflicts = flipped.winding_conflicts()
    assert int(conflicts.sum()) == 3 + 4
    assert set(np.unique(pair[conflicts]).tolist()) >= {3, 50, 51}
    # three faces around one edge (non-manifold): judged where the adjacency lists the pair
    fan = TriangleMesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [1, 1, 1]], float),
                       np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [1, 5, 2]]))
    assert fan.winding_conflicts().shape == (len(fan.face_adjacency),) and not fan.winding_conflicts().any()
    # a double-sided quad: each triangle twice, wound apart on purpose: no conflict
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    corners = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    sheet = TriangleMesh(corners, np.vstack([quad, quad[:, ::-1]]))
    assert len(sheet.face_adjacency) and not sheet.winding_conflicts().any()
    est = estimate(MultiViewData(flipped, [View("v", CAM, np.ones((12, 16, 3)))]), "median-color",
                   EstimatorConfig(sh_order=2, directions=50))
    assert est.info["winding_conflicts"] == 7
    assert any(w.startswith("7 edge(s) of the mesh join faces wound in opposite directions")
               for w in est.info["warnings"])
