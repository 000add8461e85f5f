"""One-bounce indirect shading from observed radiance: inside a closed sphere every
direction above a face sees the sphere again."""
import numpy as np

from estimator.core.data import TriangleMesh
from estimator.light.indirect import indirect_shading, indirect_transfer
from estimator.rays.raycast import RayCaster
from estimator.rays.visibility import compute_visibility, sphere_sampling

from .meshes import sphere


def test_inside_a_uniform_sphere_the_indirect_shading_is_the_radiance():
    ball = sphere(3)
    inside = TriangleMesh(ball.vertices, ball.faces[:, ::-1])      # normals point inwards
    caster = RayCaster(inside)
    sampling = sphere_sampling(600)
    visibility = compute_visibility(caster, sampling)
    assert visibility.unpack(slice(0, 10)).mean() < 0.6                # the upper hemisphere is all blocked
    radiance = np.tile([0.2, 0.5, 1.0], (inside.num_faces, 1))
    shading = indirect_shading(caster, sampling, visibility, radiance)
    # (1/pi) int_hemisphere cos dw = 1: the shading is the surrounding radiance (quadrature error ~2 %)
    np.testing.assert_allclose(shading, radiance, rtol=0.04)
    # a dark half contributes nothing: faces see about half of it
    half = radiance * (inside.centroids[:, 1:2] > 0)
    assert 0.25 < indirect_shading(caster, sampling, visibility, half)[:, 2].mean() < 0.75


def test_a_convex_object_receives_no_indirect_light():
    mesh = sphere(2)
    caster = RayCaster(mesh)
    sampling = sphere_sampling(300)
    shading = indirect_shading(caster, sampling, compute_visibility(caster, sampling), np.ones((mesh.num_faces, 3)))
    assert np.abs(shading).max() < 1e-3


def test_the_transfer_operator_is_the_traced_shading_held_whole():
    """indirect_transfer @ radiance is indirect_shading(radiance) for any radiance, traced in
    any chunking: the operator a solve keeps for its refits changes nothing but the time."""
    ball = sphere(2)
    inside = TriangleMesh(ball.vertices, ball.faces[:, ::-1])
    caster = RayCaster(inside)
    sampling = sphere_sampling(300)
    visibility = compute_visibility(caster, sampling)
    radiance = np.random.default_rng(0).uniform(0.0, 1.0, (inside.num_faces, 3))
    transfer = indirect_transfer(caster, sampling, visibility, max_rays=5_000)   # several chunks
    assert transfer.shape == (inside.num_faces, inside.num_faces) and transfer.nnz > 0
    np.testing.assert_allclose(transfer @ radiance, indirect_shading(caster, sampling, visibility, radiance),
                               rtol=1e-12, atol=1e-15)
    convex = RayCaster(sphere(1))
    assert indirect_transfer(convex, sampling, compute_visibility(convex, sampling)).nnz == 0
