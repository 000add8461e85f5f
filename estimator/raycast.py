"""Mitsuba ray queries on a TriangleMesh: face-ID buffers and shadow tests.

All queries are batched Dr.Jit calls over many rays; nothing loops over rays in Python.
"""
from __future__ import annotations

import numpy as np

from . import backend
from .camera import Camera
from .data import TriangleMesh


def mitsuba_mesh(mesh: TriangleMesh, name: str = "mesh", props=None):
    """A ``mi.Mesh`` with the vertices and faces of ``mesh`` in its face order.

    No vertex normals: Mitsuba shades with the geometric (flat) face normals.
    ``props`` is an optional ``mi.Properties`` (to attach a BSDF).
    """
    mi = backend.set_variant()
    args = (name, mesh.vertices.shape[0], mesh.num_faces)
    m = mi.Mesh(*args, has_vertex_normals=False, has_vertex_texcoords=False,
                props=props) if props is not None else mi.Mesh(*args, has_vertex_normals=False)
    params = mi.traverse(m)
    params["vertex_positions"] = mi.Float(mesh.vertices.astype(np.float32).ravel())
    params["faces"] = mi.UInt32(mesh.faces.astype(np.uint32).ravel())
    params.update()
    return m


class RayCaster:
    """A Mitsuba scene holding one mesh, for batched intersection and shadow queries.

    Parameters
    ----------
    mesh : TriangleMesh
    variant : optional Mitsuba variant (see :mod:`estimator.backend`).
    """

    def __init__(self, mesh: TriangleMesh, variant: str | None = None):
        self.mi = backend.set_variant(variant)
        self.mesh = mesh
        self.scene = self.mi.load_dict({
            "type": "scene",
            "embree_use_robust_intersections": True,
            "mesh": mitsuba_mesh(mesh),
        })
        self.scale = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))

    def _rays(self, origins: np.ndarray, directions: np.ndarray, tmax: float | None = None):
        mi = self.mi
        o = mi.Point3f(*(np.ascontiguousarray(origins[:, i], dtype=np.float32) for i in range(3)))
        d = mi.Vector3f(*(np.ascontiguousarray(directions[:, i], dtype=np.float32) for i in range(3)))
        ray = mi.Ray3f(o, d)
        if tmax is not None:
            ray.maxt = tmax
        return ray

    def first_hit_faces(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Index of the first face hit by each ray, -1 on a miss.

        Parameters
        ----------
        origins, directions : (N, 3)

        Returns
        -------
        (N,) int64
        """
        if len(origins) == 0:
            return np.zeros(0, dtype=np.int64)
        pi = self.scene.ray_intersect_preliminary(self._rays(origins, directions))
        hit = np.asarray(pi.is_valid(), dtype=bool)
        prim = np.asarray(pi.prim_index, dtype=np.int64)
        return np.where(hit, prim, -1)

    def first_hits(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(face (N,) int64 with -1 on a miss, distance t (N,) float64, inf on a miss)."""
        if len(origins) == 0:
            return np.zeros(0, dtype=np.int64), np.zeros(0)
        pi = self.scene.ray_intersect_preliminary(self._rays(origins, directions))
        hit = np.asarray(pi.is_valid(), dtype=bool)
        return (np.where(hit, np.asarray(pi.prim_index, dtype=np.int64), -1),
                np.where(hit, np.asarray(pi.t, dtype=np.float64), np.inf))

    def face_id_buffer(self, camera: Camera) -> np.ndarray:
        """(H, W) int64 face seen through each pixel centre, -1 for background."""
        o, d = camera.pixel_rays()
        return self.first_hit_faces(o, d).reshape(camera.height, camera.width)

    def pure_face_buffer(self, camera: Camera) -> np.ndarray:
        """(H, W) face seen through each pixel centre, -1 where the pixel is background
        *or* not covered by that face alone (a pixel corner ray hits another face or
        nothing). Pure pixels carry one face's colour even with antialiased images."""
        centre = self.face_id_buffer(camera)
        corner_cam = Camera(camera.c2w, camera.fx, camera.fy, camera.cx + 0.5, camera.cy + 0.5,
                            camera.width + 1, camera.height + 1)
        corners = self.face_id_buffer(corner_cam)      # (H+1, W+1): ray through each pixel corner
        pure = ((corners[:-1, :-1] == centre) & (corners[1:, :-1] == centre)
                & (corners[:-1, 1:] == centre) & (corners[1:, 1:] == centre))
        return np.where(pure, centre, -1)

    def occluded(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(N,) bool: True when the ray (N, 3) x (N, 3) hits any geometry."""
        if len(origins) == 0:
            return np.zeros(0, dtype=bool)
        return np.asarray(self.scene.ray_test(self._rays(origins, directions)), dtype=bool)
