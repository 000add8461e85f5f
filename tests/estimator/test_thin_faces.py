"""Thin faces: on a mesh the images resolve, the faces no pure pixel covers are observed through
their unmixed footprints (``Observations.thin``) and join the default's estimate under its light
(``estimator.methods.retinex_segmented.thin``)."""
from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from estimator import MultiViewData, View, estimate
from estimator.core.camera import Camera, look_at
from estimator.methods.retinex_segmented.thin import joined_to_regions, thin_faces, unanimous_neighbour
from estimator.methods.retinex_segmented.values import Hypothesis, LightSource, Shading
from estimator.pipeline.observations import Observations, gather_observations
from estimator.pipeline.prepared import prepare
from estimator.rays.raycast import RayCaster

from .meshes import sphere, with_slivers
from .micro import micro_config, micro_scene


def test_slivers_on_a_resolved_mesh_are_observed_through_their_footprints():
    """A sphere of 320 faces seen at 64 px (faces of tens of pixels) with 40 faces split so that
    a sliver of about 1.5 % of their area runs along an edge; every face a random colour and
    each pixel the mean of 8 x 8 sub-pixel rays (a box filter). The mesh is resolved (no face
    ``unresolved``); the slivers with rows are thin, and their rows come back within 10 % of
    their own colour at the median (a neighbour of another random colour shares each of their
    pixels). Without sub-pixel samples nothing unmixes them: they have no row, none is thin."""
    rng = np.random.default_rng(3)
    mesh, slivers = with_slivers(sphere(2), rng.choice(320, 40, replace=False))
    caster = RayCaster(mesh)
    colour = rng.uniform(0.1, 1.0, size=(mesh.num_faces, 3))
    eyes = [[0, 0, 4], [0.3, 0.2, 4], [-0.2, 0.35, 4], [0.15, -0.3, 4], [4, 0, 0.5], [0, 4, 0.3], [-4, 0.5, 0],
            [0, -4, 0.5]]
    views = []
    for i, eye in enumerate(eyes):
        cam = Camera.from_fov(look_at(eye, [0, 0, 0]), 30, 64, 64)
        fine = caster.subpixel_faces(cam, 8, np.arange(64 * 64))
        image = np.where(fine[..., None] >= 0, colour[np.maximum(fine, 0)], 0.0).mean(axis=1)
        views.append(View(f"v{i}", cam, image.reshape(64, 64, 3).astype(np.float32)))
    obs = gather_observations(caster, views)
    rows = np.bincount(obs.face, minlength=mesh.num_faces) > 0
    assert obs.unresolved is None and obs.thin is not None
    assert rows[slivers].sum() >= 20 and np.all(obs.thin[slivers[rows[slivers]]])
    thin_rows = obs.thin[obs.face]
    assert np.median(np.abs(obs.rgb[thin_rows] / colour[obs.face[thin_rows]] - 1)) < 0.10
    centres = gather_observations(caster, views, subpixel_samples=1)
    assert centres.thin is None and not np.any(np.isin(centres.face, slivers))


@pytest.fixture(scope="module")
def slivered_micro():
    """The micro scene (two uniform regions, matte) at 64 px with slivers in 12 faces whose
    neighbours all lie in their region and in 3 faces along the regions' border, the sliver on
    the border edge; the default's estimate of it."""
    base = sphere(2)
    top = base.centroids[:, 1] > 0.2
    pairs = base.face_adjacency
    mixed = np.zeros(base.num_faces, bool)
    mixed[pairs[top[pairs[:, 0]] != top[pairs[:, 1]]].ravel()] = True
    # the face across each face's first edge (a, b), along which its sliver runs
    across = np.full(base.num_faces, -1)
    for p, q in ((pairs[:, 0], pairs[:, 1]), (pairs[:, 1], pairs[:, 0])):
        first = base.faces[p][:, :2]
        on = np.all(np.any(first[:, :, None] == base.faces[q][:, None, :], axis=2), axis=1)
        across[p[on]] = q[on]
    rng = np.random.default_rng(0)
    inside = rng.choice(np.nonzero(~mixed)[0], 12, replace=False)
    border = np.nonzero(top != top[across])[0][:3]
    mesh, slivers = with_slivers(base, np.concatenate([inside, border]))
    config = micro_config()
    data, truth = micro_scene(config, specular=0.0, mesh=mesh, size=64)
    return estimate(data, "retinex-segmented", config), truth, slivers[:12], slivers[12:], data


def test_thin_faces_inside_a_region_take_its_albedo_and_those_on_its_border_none(slivered_micro):
    """The slivers inside a region that have rows join it with its albedo (its faces' own, to
    1e-4 after the gauge, as every estimated face); a sliver along the border of two regions
    (its neighbours in both) is left out: its pixels mix the two albedos."""
    est, truth, inside, border, _ = slivered_micro
    assert est.info["uniform_regions"] == 2 and est.info["unresolved_faces"] == 0
    joined = inside[est.observed[inside]]
    assert len(joined) >= 4
    o = est.observed
    gauge = np.sum(truth.diffuse[o] * est.diffuse[o], 0) / np.sum(est.diffuse[o] ** 2, 0)
    np.testing.assert_allclose(est.diffuse[o] * gauge, truth.diffuse[o], rtol=1e-4)
    top = est.labels[np.argmax(truth.diffuse[:, 0])]
    for face in joined:
        region = est.labels == est.labels[face]
        assert region.sum() > 100 and est.labels[face] == (top if truth.diffuse[face, 0] > 0.5 else 1 - top)
    assert not est.observed[border].any()


def test_the_other_faces_and_the_light_are_those_of_a_run_without_thin_rows(slivered_micro):
    """Without sub-pixel samples nothing unmixes the slivers, so they have no rows: that
    run's light and its albedo of every face both runs estimate are the default's (the thin
    faces' rows take no part in the fit); the default's count of thin faces is recorded."""
    est, _, inside, _, data = slivered_micro
    plain = estimate(data, "retinex-segmented", micro_config(subpixel_samples=1))
    assert plain.info["outside_faces"]["thin"] == 0 < est.info["outside_faces"]["thin"]
    assert est.info["outside_faces"]["joined"] >= int(est.observed.sum() - np.sum(est.observed & plain.observed))
    np.testing.assert_allclose(est.pseudo_sh, plain.pseudo_sh, rtol=1e-9, atol=1e-12)
    both = est.observed & plain.observed
    assert both.sum() > 250 and not plain.observed[inside].any()
    np.testing.assert_allclose(est.diffuse[both], plain.diffuse[both], rtol=1e-9)


@pytest.mark.parametrize("light_faces", [5000, 100])
def test_faces_seen_only_at_grazing_angles_join_their_region(light_faces):
    """With ``min_cos_view`` 0.8 the micro scene's 8 cameras keep rows of under half of its
    320 faces; the 150-odd seen only beyond it are outside the fit and most join the region
    all their lit neighbours lie in, with its albedo (exact after the gauge, as the fitted
    faces'), whether the light is found on the faces or on 100 clusters of them
    (:func:`estimator.methods.retinex_segmented.clusters.extend`)."""
    config = micro_config(min_cos_view=0.8, light_faces=light_faces)
    data, truth = micro_scene(config, specular=0.0)
    est = estimate(data, "retinex-segmented", config)
    assert ("light_faces" in est.info) == (light_faces < 320)
    counts = est.info["outside_faces"]
    assert counts["thin"] == 0 and counts["grazing"] > 150 and counts["joined"] > 150
    assert est.observed.sum() > 300
    o = est.observed
    gauge = np.sum(truth.diffuse[o] * est.diffuse[o], 0) / np.sum(est.diffuse[o] ** 2, 0)
    np.testing.assert_allclose(est.diffuse[o] * gauge, truth.diffuse[o], rtol=1e-4)


def test_view_gains_come_from_the_rows_the_fit_takes(slivered_micro):
    """Each view's images scaled by its own gain, ``view_gains`` on: the gains are fitted to the
    rows the default's fit takes, so its light and the other faces' albedos are those of the run
    without thin rows (they had moved the light by 5e-11 on noise-free images, by 3e-3 with
    noise)."""
    _, _, _, _, data = slivered_micro
    gains = np.random.default_rng(5).uniform(0.6, 1.6, (len(data.views), 3))
    scaled = MultiViewData(data.mesh, [View(v.name, v.camera, (v.rgb * g).astype(np.float32), v.alpha)
                                       for v, g in zip(data.views, gains)])
    est = estimate(scaled, "retinex-segmented", micro_config(view_gains=True))
    plain = estimate(scaled, "retinex-segmented", micro_config(view_gains=True, subpixel_samples=1))
    np.testing.assert_array_equal(est.pseudo_sh, plain.pseudo_sh)
    both = est.observed & plain.observed
    np.testing.assert_array_equal(est.diffuse[both], plain.diffuse[both])


def test_thin_rows_stay_where_no_other_face_has_a_kept_row(slivered_micro):
    """``Prepared.without_thin`` drops the thin faces' rows, unless every kept row is a thin
    face's: then they are all there is to solve from, and the problem is returned as it is."""
    _, _, _, _, data = slivered_micro
    prep = prepare(data, micro_config())
    dropped = prep.without_thin()
    assert not np.any(prep.all_obs.thin[dropped.all_obs.face]) and len(dropped.obs.face) < len(prep.obs.face)
    every = np.ones(prep.obs.num_faces, bool)
    alone = replace(prep, obs=replace(prep.obs, thin=every), all_obs=replace(prep.all_obs, thin=every))
    assert alone.without_thin() is alone


def test_thin_faces_seen_only_at_grazing_angles_can_keep_their_rows():
    """With ``min_cos_view`` 0.8 the micro scene's thin faces have no kept row:
    ``without_thin(keep_grazing=True)`` (the cluster path's) keeps their rows in ``all_obs``,
    where they join as the other faces seen only at grazing angles do, and drops only the
    thin faces with kept rows; ``without_thin()`` drops every thin face's rows."""
    config = micro_config(min_cos_view=0.8)
    data, _ = micro_scene(config, specular=0.0)
    prep = prepare(data, config)
    thin, kept = prep.all_obs.thin, prep.obs.observed_faces()
    grazing = thin & ~kept
    assert grazing.any()
    plain, keeping = prep.without_thin(), prep.without_thin(keep_grazing=True)
    np.testing.assert_array_equal(plain.obs.face, keeping.obs.face)
    for dropped, expected in ((plain, thin), (keeping, thin & kept)):
        rows = dropped.all_obs.observed_faces()
        assert not np.any(rows & expected)
        assert np.array_equal(rows & thin, thin & ~expected)


def test_methods_that_do_not_join_thin_faces_never_see_their_rows(slivered_micro):
    """The other methods solve every face with rows as its own (or its cluster's): the thin
    faces' rows are dropped before their solve, so a per-face method estimates none of the
    slivers the default joined, and its estimate is the one it makes of the mesh without them."""
    est, _, inside, _, data = slivered_micro
    joined = inside[est.observed[inside]]
    config = micro_config()
    per_face = estimate(data, "median-color", config)
    assert len(joined) and not per_face.observed[joined].any()
    assert per_face.info["observations_all"] < est.info["observations_all"]


def test_a_face_joins_the_region_all_its_labelled_neighbours_share():
    """Faces 0-4 in a chain 0-1-2-3-4 (edges (0, 1), (1, 2), (2, 3), (3, 4)): face 1 between
    regions 0 and 1 has none, face 3 between region 1 and an unlabelled face takes 1, a face
    without a labelled neighbour none."""
    labels = np.array([0, -1, 1, -1, -1])
    a, b = np.array([0, 1, 2, 3]), np.array([1, 2, 3, 4])
    np.testing.assert_array_equal(unanimous_neighbour(labels, a, b, 2), [-1, -1, -1, 1, -1])


def test_faces_outside_the_fit_join_as_deep_as_their_region_reaches():
    """A chain of 40 faces lit alike: faces 0-4 are fitted in region 0 (albedo 0.6), faces 35-39
    in region 1 (0.2), the 30 between are outside the fit, faces 5-12 of region 0's colour and
    13-34 of region 1's. Each joins its own region however far from the fit it lies (21 rounds
    from region 1), and region 0 stops where its colour ends, though face 13 has region 0's
    neighbours alone for several rounds; face 13 then borders both regions and stays out."""
    f = 40
    albedo = np.where(np.arange(f) < 13, 0.6, 0.2)[:, None] * np.ones(3)
    fitted = (np.arange(f) < 5) | (np.arange(f) >= 35)
    labels = np.where(np.arange(f) < 5, 0, np.where(np.arange(f) >= 35, 1, -1))
    shade = np.ones((f, 3))
    h = Hypothesis(albedo * shade, np.ones((1, 3)), Shading(np.ones((f, 1))), np.where(fitted[:, None], albedo, 0.0),
                   fitted, labels, 2, 1.0, LightSource.EDGES_AND_REGIONS, None)
    ctx = SimpleNamespace(usable=fitted, edges=np.column_stack([np.arange(f - 1), np.arange(1, f)]),
                          config=SimpleNamespace(segment_threshold=0.12))
    joined = joined_to_regions(ctx, h, ~fitted, shade)
    border = np.arange(f) == 13
    np.testing.assert_array_equal(joined.lit, ~border)
    np.testing.assert_array_equal(joined.labels, np.where(np.arange(f) < 13, 0, np.where(border, -1, 1)))
    np.testing.assert_allclose(joined.albedo[~border], albedo[~border])


def test_thin_faces_are_those_with_rows_unless_no_other_face_has_one():
    """Faces 0-3, rows of faces 0, 1 and 2: with 1 and 3 thin, face 1 is (3 has no row); with
    0, 1 and 2 thin there is no other face to fit, so none is set apart (None); without a
    thin face, None."""
    def rows(thin):
        face = np.array([0, 0, 1, 2])
        return Observations(face, np.ones((4, 3)), np.tile([0.0, 0.0, 1.0], (4, 1)), 4, 2, thin=thin)
    np.testing.assert_array_equal(thin_faces(rows(np.array([False, True, False, True]))), [False, True, False, False])
    assert thin_faces(rows(np.array([True, True, True, False]))) is None
    assert thin_faces(rows(None)) is None
