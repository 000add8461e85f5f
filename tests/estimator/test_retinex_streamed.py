"""The sub-mesh a streamed ``retinex-segmented`` finds its light on (:func:`patch_faces`)."""
from __future__ import annotations

import numpy as np

from estimator.methods.retinex_segmented.streamed import patch_faces

from .meshes import sphere


def test_patches_are_contiguous_observed_faces_spread_over_the_object():
    mesh = sphere(5)                                                  # 20,480 faces
    observed = np.nonzero(mesh.centroids[:, 1] > -0.5)[0]            # the underside unseen
    faces = patch_faces(mesh.centroids, observed, 2000, 40)
    assert np.all(np.isin(faces, observed)) and np.all(np.diff(faces) > 0)
    assert 1000 <= len(faces) <= 2000                                 # 40 patches of 50, overlapping at most in part
    # contiguous: nearly every face of a patch has a neighbour in the sub-mesh (a face drawn
    # alone at this density would have one in ~1 - (1 - 0.1)^3 = 27 % of cases)
    inside = np.zeros(mesh.num_faces, bool)
    inside[faces] = True
    adjacency = mesh.face_adjacency
    neighbour = np.zeros(mesh.num_faces, bool)
    both = inside[adjacency[:, 0]] & inside[adjacency[:, 1]]
    neighbour[adjacency[both].ravel()] = True
    assert neighbour[faces].mean() > 0.97
    # spread: the patches' mean normals point to many sides (the light is seen from them)
    normals = mesh.face_normals[faces]
    assert normals[:, 1].min() < 0 < normals[:, 1].max()
    assert np.ptp(np.arctan2(normals[:, 0], normals[:, 2])) > 5.0
    # seeded
    np.testing.assert_array_equal(faces, patch_faces(mesh.centroids, observed, 2000, 40))


def test_every_observed_face_when_they_are_few():
    mesh = sphere(2)
    observed = np.array([7, 3, 100])
    np.testing.assert_array_equal(patch_faces(mesh.centroids, observed, 10, 4), [3, 7, 100])
