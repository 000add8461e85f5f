"""The clusters of faces ``retinex-segmented`` finds its light on beyond ``light_faces`` or on a mesh
denser than its photos (:func:`face_clusters`, :func:`cluster_count`), and the observations merged per
cluster and view (:meth:`Observations.merged`)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from estimator.methods.retinex_segmented.clusters import RESOLVED_PIXELS, cluster_count, face_clusters
from estimator.pipeline.observations import Observations

from .meshes import sphere


def test_clusters_are_compact_patches_of_the_observed_faces():
    mesh = sphere(5)                                                  # 20,480 faces
    observed = np.nonzero(mesh.centroids[:, 1] > -0.5)[0]            # the underside unseen
    cluster, representative = face_clusters(mesh, observed, 500)
    assert len(representative) == 500 and np.all(np.isin(representative, observed))
    assert np.all(cluster[observed] >= 0) and np.all(np.delete(cluster, observed) == -1)
    np.testing.assert_array_equal(cluster[representative], np.arange(500))   # each represents its own
    sizes = np.bincount(cluster[observed], minlength=500)
    assert sizes.min() >= 1 and sizes.max() <= 6 * len(observed) / 500
    # compact: a face lies within a few clusters' sides of its representative, and most
    # adjacent faces share their cluster
    side = np.sqrt(mesh.areas[observed].sum() / 500)
    reach = np.linalg.norm(mesh.centroids[observed] - mesh.centroids[representative[cluster[observed]]], axis=1)
    assert np.percentile(reach, 99) < 2 * side
    a, b = mesh.face_adjacency.T
    both = (cluster[a] >= 0) & (cluster[b] >= 0)
    assert np.mean(cluster[a][both] == cluster[b][both]) > 0.7
    np.testing.assert_array_equal(cluster, face_clusters(mesh, observed, 500)[0])   # seeded


def test_every_observed_face_its_own_cluster_when_they_are_few():
    mesh = sphere(2)
    cluster, representative = face_clusters(mesh, np.array([3, 7, 100]), 10)
    np.testing.assert_array_equal(representative, [3, 7, 100])
    np.testing.assert_array_equal(cluster[[3, 7, 100]], [0, 1, 2])
    assert np.sum(cluster >= 0) == 3


def test_merged_observations_are_area_weighted_means_per_cluster_and_view():
    face = np.array([0, 1, 1, 2, 3])
    view = np.array([0, 0, 1, 0, 1])
    rgb = np.array([[1.0, 1, 1], [3, 3, 3], [5, 5, 5], [7, 7, 7], [9, 9, 9]])
    direction = np.array([[0.0, 0, 1], [0, 1, 0], [0, 0, 1], [1, 0, 0], [0, 0, 1]])
    obs = Observations(face, rgb, direction, 4, 2, None, view)
    merged = obs.merged(np.array([0, 0, 1, -1]), 2, np.array([1.0, 3.0, 1.0, 1.0]))
    np.testing.assert_array_equal(merged.face, [0, 0, 1])
    np.testing.assert_array_equal(merged.view, [0, 1, 0])
    np.testing.assert_allclose(merged.rgb[:, 0], [(1 + 3 * 3) / 4, 5, 7])      # face 3 left out
    np.testing.assert_allclose(merged.view_dir[0], np.array([0, 3, 1]) / np.sqrt(10))
    assert merged.num_faces == 2 and merged.num_views == 2


def _problem(faces: int, unresolved: bool, footprint: float | None):
    obs = Observations(np.arange(faces), np.ones((faces, 3)), np.zeros((faces, 3)), faces, 1,
                       unresolved=np.ones(faces, bool) if unresolved else None, footprint_pixels=footprint)
    return SimpleNamespace(obs=obs, all_obs=obs)


def test_a_resolved_mesh_clusters_only_beyond_light_faces():
    assert cluster_count(_problem(5000, False, None), 20_000, 5000) == 5000        # every face its own
    assert cluster_count(_problem(50_000, False, None), 20_000, 50_000) == 20_000


@pytest.mark.parametrize("footprint", [1.0, 1.35, 3.0])
def test_a_mesh_denser_than_its_photos_clusters_to_resolved_footprints(footprint):
    """Each cluster's rows average RESOLVED_PIXELS pixels: 1 pixel per face gives clusters of
    about 11.7 faces, whatever ``light_faces`` allows."""
    count = cluster_count(_problem(50_000, True, footprint), 20_000, 50_000)
    assert count == int(np.ceil(50_000 * footprint / RESOLVED_PIXELS))
    assert 50_000 * footprint / count == pytest.approx(RESOLVED_PIXELS, rel=1e-3)
    assert cluster_count(_problem(50_000, True, footprint), 100, 50_000) == 100      # the cap still holds


def test_resolved_pixels_is_the_patch_half_of_whose_pixels_are_whole():
    side = np.sqrt(RESOLVED_PIXELS)
    assert (side - 1) ** 2 == pytest.approx(RESOLVED_PIXELS / 2)
    assert cluster_count(_problem(1000, True, 2 * RESOLVED_PIXELS), 20_000, 1000) == 1000   # faces already resolved
