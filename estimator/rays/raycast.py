"""Mitsuba ray queries on a TriangleMesh: first hits and face-ID buffers (the shadow
function traces its rays in one Dr.Jit kernel, see :mod:`estimator.rays.visibility`).

All queries are batched Dr.Jit calls over many rays; nothing loops over rays in Python.
"""
from __future__ import annotations

from collections import OrderedDict

import numpy as np

from ..core.camera import Camera
from ..core.data import TriangleMesh
from ..core.errors import InputError, is_whole
from . import backend


def mitsuba_mesh(mesh: TriangleMesh, name: str = "mesh", props=None, uv: np.ndarray | None = None):
    """A ``mi.Mesh`` with the vertices and faces of ``mesh`` in its face order.

    No vertex normals: Mitsuba shades with the geometric (flat) face normals.
    ``props`` is an optional ``mi.Properties`` (to attach a BSDF); ``uv`` optional per-vertex
    texture coordinates (V, 2) (a UV atlas's, :func:`estimator.core.atlas.uv_atlas`).
    """
    mi = backend.set_variant()
    m = mi.Mesh(name, mesh.vertices.shape[0], mesh.num_faces, has_vertex_normals=False,
                has_vertex_texcoords=uv is not None, **({} if props is None else {"props": props}))
    params = mi.traverse(m)
    params["vertex_positions"] = mi.Float(mesh.vertices.astype(np.float32).ravel())
    params["faces"] = mi.UInt32(mesh.faces.astype(np.uint32).ravel())
    if uv is not None:
        params["vertex_texcoords"] = mi.Float(np.asarray(uv, dtype=np.float32).ravel())
    params.update()
    return m


# face-ID buffers a caster keeps (int32: 128 buffers of 512 x 512)
BUFFER_CACHE_BYTES = 128 * 2**20

MAX_COORDINATE = 1e15   # float32: squared distances stay below 1e30 (they overflow at 3.4e38)

MISS = -1        # first_hit_faces: the ray hits nothing
ELSEWHERE = -2   # ClusterCaster.first_hit_faces: the ray hits a face in no cluster


class RayCaster:
    """A Mitsuba scene holding one mesh (robust intersections), for batched ray queries.

    Parameters
    ----------
    mesh : TriangleMesh
    variant : optional Mitsuba variant (see :mod:`estimator.rays.backend`).
    """

    def __init__(self, mesh: TriangleMesh, variant: str | None = None):
        reach = float(np.abs(mesh.vertices).max())
        if reach > MAX_COORDINATE:
            raise InputError(f"the mesh reaches {reach:.3g} from the origin (at most {MAX_COORDINATE:g}): rays are "
                             "traced in float32, whose squared distances overflow there; rescale the mesh and the "
                             "cameras")
        self.mi = backend.set_variant(variant)
        self.mesh = mesh
        self.scene = self.mi.load_dict({
            "type": "scene",
            "embree_use_robust_intersections": True,
            "mesh": mitsuba_mesh(mesh),
        })
        self.scale = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
        # face-ID buffers by (kind, camera), least recently used first, at most BUFFER_CACHE_BYTES
        self._buffers: OrderedDict[tuple, np.ndarray] = OrderedDict()
        # shadow functions by sampling directions (visibility.shadow_function): the mesh's, so
        # every estimate and prediction a run makes with this caster shares them
        self.shadow_functions: dict[bytes, object] = {}

    def _rays(self, origins: np.ndarray, directions: np.ndarray, tmax: float | None = None):
        """An ``mi.Ray3f`` of N rays from origins and directions (N, 3) (checked by
        :func:`_check_rays`)."""
        mi = self.mi
        o = mi.Point3f(*(np.ascontiguousarray(origins[:, i], dtype=np.float32) for i in range(3)))
        d = mi.Vector3f(*(np.ascontiguousarray(directions[:, i], dtype=np.float32) for i in range(3)))
        ray = mi.Ray3f(o, d)
        if tmax is not None:
            ray.maxt = tmax
        return ray

    def _pixel_rays(self, cameras: list[Camera]):
        """An ``mi.Ray3f`` through every pixel centre of each camera in turn (row-major), the
        same float32 rays as :meth:`Camera.pixel_rays` gives, made per axis rather than as
        (H*W, 3) float64 arrays whose columns are gathered (24 views at 256^2: the buffers take
        0.25 s this way, 0.31 s that way)."""
        directions = np.concatenate([cam.pixel_directions() for cam in cameras], axis=1)
        return self._camera_rays(cameras, [cam.width * cam.height for cam in cameras], directions)

    def _camera_rays(self, cameras: list[Camera], counts: list[int], directions: np.ndarray):
        """An ``mi.Ray3f`` from each camera's centre along its ``counts`` directions in turn,
        ``directions`` (3, sum(counts)) world unit vectors, in float32 per axis."""
        centres = np.array([cam.center for cam in cameras], dtype=np.float32)   # (V, 3)
        return self.mi.Ray3f(self.mi.Point3f(*(np.repeat(centres[:, i], counts) for i in range(3))),
                             self.mi.Vector3f(*directions.astype(np.float32)))

    def _first_hits(self, ray) -> np.ndarray:
        """(N,) int64 first face hit by each ray of an ``mi.Ray3f``, :data:`MISS` on a miss."""
        pi = self.scene.ray_intersect_preliminary(ray)
        hit = np.asarray(pi.is_valid(), dtype=bool)
        prim = np.asarray(pi.prim_index, dtype=np.int64)
        return np.where(hit, prim, MISS)

    def first_hit_faces(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Index of the first face hit by each ray, :data:`MISS` (-1) on a miss.

        Parameters
        ----------
        origins, directions : (N, 3)

        Returns
        -------
        (N,) int64
        """
        _check_rays(origins, directions)
        if len(origins) == 0:
            return np.zeros(0, dtype=np.int64)
        return self._first_hits(self._rays(origins, directions))

    def escapes(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(N,) bool: each ray (origins, directions (N, 3)) hits nothing (a shadow ray that
        escapes). Mitsuba's ``ray_test`` stops at any hit, about half the time of
        :meth:`first_hit_faces`, which finds the first."""
        _check_rays(origins, directions)
        if len(origins) == 0:
            return np.zeros(0, dtype=bool)
        return ~np.asarray(self.scene.ray_test(self._rays(origins, directions)), dtype=bool)

    def pixel_hits(self, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
        """Where each pixel centre's ray first meets the mesh: (face (H*W,) int64, -1 on a
        miss; point (H*W, 3) float64, NaN on a miss), from the camera's face-ID buffer (traced
        once and kept, :meth:`face_id_buffers`) and the hit face's plane."""
        face = self.face_id_buffer(camera).ravel().astype(np.int64)
        hit = np.nonzero(face >= 0)[0]
        dirs = camera.subpixel_directions(hit, 1).T   # the hit pixels' centre rays only
        normal = self.mesh.face_normals[face[hit]]
        corner = self.mesh.vertices[self.mesh.faces[face[hit], 0]]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.sum(normal * (corner - camera.center), axis=1) / np.sum(normal * dirs, axis=1)
        points = np.full((len(face), 3), np.nan)
        points[hit] = camera.center + t[:, None] * dirs
        face[hit[~np.isfinite(t)]] = MISS   # a ray along its face's plane (grazing)
        return face, points

    def face_id_buffer(self, camera: Camera) -> np.ndarray:
        """(H, W) int32 face seen through each pixel centre, -1 for background (read-only)."""
        return self.face_id_buffers([camera], pure=False)[0]

    def face_id_buffers(self, cameras: list[Camera], pure: bool = False,
                        max_rays: int = 4_000_000) -> list[np.ndarray]:
        """Face-ID buffers of many cameras, traced in batches of up to ``max_rays`` rays.

        With ``pure=True`` a pixel keeps its face only when the rays through its
        four corners hit that same face (-1 otherwise): such pixels are covered by
        one face alone, so their colour is that face's even in antialiased images.
        Buffers are kept per camera (pose, intrinsics, size) up to
        :data:`BUFFER_CACHE_BYTES`, the least recently used dropped first: the pose check,
        the pose refinement and the observations trace the same views
        again and again, and only a moved camera is traced anew.

        Returns
        -------
        list of (H, W) int32 arrays, -1 for background (or impure pixels); read-only.
        """
        keys = [_camera_key(cam) for cam in cameras]
        kind = "pure" if pure else "centre"
        held = {k: self._buffers[k] for key in keys for k in (("centre", key), (kind, key)) if k in self._buffers}
        # a centre buffer is traced only where it is asked for, or where a pure one must be made from it
        centres = {key: cam for cam, key in zip(cameras, keys)
                   if ("centre", key) not in held and (kind, key) not in held}
        corners = {key: Camera(cam.c2w, cam.fx, cam.fy, cam.cx + 0.5, cam.cy + 0.5, cam.width + 1, cam.height + 1)
                   for cam, key in zip(cameras, keys) if pure and (kind, key) not in held}   # (H+1) x (W+1) rays
        traced = self._trace(list(centres.values()) + list(corners.values()), max_rays)
        for key, buffer in zip(centres, traced):
            held[("centre", key)] = _read_only(buffer)
        for key, corner in zip(corners, traced[len(centres):]):
            centre = held[("centre", key)]
            same = ((corner[:-1, :-1] == centre) & (corner[1:, :-1] == centre)
                    & (corner[:-1, 1:] == centre) & (corner[1:, 1:] == centre))
            held[("pure", key)] = _read_only(np.where(same, centre, -1))
        for k, buffer in held.items():
            self._keep(k, buffer)
        return [held[(kind, key)] for key in keys]

    def subpixel_faces(self, camera: Camera, samples: int, pixels: np.ndarray) -> np.ndarray:
        """(P, samples^2) int64 the face each of ``samples`` x ``samples`` sub-pixel rays through
        each of ``pixels`` (P,) (row-major indices) hits, -1 on a miss
        (:meth:`Camera.subpixel_directions`; not kept)."""
        if not is_whole(samples) or samples < 1:
            raise InputError(f"subpixel_faces: samples must be an integer >= 1, got {samples!r}")
        s = int(samples)
        if len(pixels) == 0:   # Dr.Jit aborts the process on a launch of no rays
            return np.zeros((0, s * s), dtype=np.int64)
        directions = camera.subpixel_directions(pixels, s)
        return self._first_hits(self._camera_rays([camera], [directions.shape[1]], directions)).reshape(-1, s * s)

    def _keep(self, key: tuple, buffer: np.ndarray) -> None:
        """Hold ``buffer`` under ``key`` as the most recently used, dropping the least recently
        used beyond :data:`BUFFER_CACHE_BYTES`."""
        self._buffers[key] = buffer
        self._buffers.move_to_end(key)
        total = sum(b.nbytes for b in self._buffers.values())
        while total > BUFFER_CACHE_BYTES and len(self._buffers) > 1:
            _, dropped = self._buffers.popitem(last=False)
            total -= dropped.nbytes

    def _trace(self, grids: list[Camera], max_rays: int) -> list[np.ndarray]:
        """(H, W) first-hit faces of each camera's pixel grid, in batches of up to ``max_rays`` rays."""
        buffers: list[np.ndarray] = []
        batch: list[Camera] = []
        for grid in grids + [None]:
            size = sum(g.width * g.height for g in batch)
            if batch and (grid is None or size + grid.width * grid.height > max_rays):
                ids = self._first_hits(self._pixel_rays(batch))
                parts = np.split(ids, np.cumsum([g.width * g.height for g in batch])[:-1])
                buffers += [b.reshape(g.height, g.width) for b, g in zip(parts, batch)]
                batch = []
            if grid is not None:
                batch.append(grid)
        return buffers


def _read_only(buffer: np.ndarray) -> np.ndarray:
    """``buffer`` as int32, read-only: a cached buffer is shared with every later caller."""
    buffer = buffer.astype(np.int32)
    buffer.flags.writeable = False
    return buffer


def _camera_key(camera: Camera) -> tuple:
    """What a camera's pixel rays depend on: its pose, intrinsics and size."""
    return (np.asarray(camera.c2w, dtype=np.float64).tobytes(), camera.fx, camera.fy, camera.cx, camera.cy,
            camera.width, camera.height)


class ClusterCaster:
    """The ray queries a solve makes on a problem whose faces are clusters of a whole mesh's
    faces (:meth:`estimator.pipeline.prepared.Prepared.clustered`), traced against the whole
    mesh: every face still blocks rays (a sun's shadow), and a hit reports the hit face's
    cluster, or :data:`ELSEWHERE` for a face in none.

    Parameters
    ----------
    whole : the caster of the whole mesh.
    cluster : (F,) the cluster of each whole-mesh face, -1 for none.
    mesh : the clustered problem's mesh (one face per cluster).
    """

    def __init__(self, whole: RayCaster, cluster: np.ndarray, mesh: TriangleMesh):
        if len(cluster) != whole.mesh.num_faces or cluster.max(initial=-1) >= mesh.num_faces:
            raise InputError(f"the clusters of a {whole.mesh.num_faces}-face mesh must be {whole.mesh.num_faces} "
                             f"indices below {mesh.num_faces}, got {len(cluster)} up to {cluster.max(initial=-1)}")
        self.whole, self.mesh, self.scale = whole, mesh, whole.scale
        self._cluster = np.where(cluster >= 0, cluster, ELSEWHERE).astype(np.int64)

    def first_hit_faces(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(N,) int64 cluster of the face first hit by each ray (origins, directions (N, 3)),
        :data:`MISS` on a miss, :data:`ELSEWHERE` when that face is in no cluster."""
        hit = self.whole.first_hit_faces(origins, directions)
        return np.where(hit >= 0, self._cluster[np.maximum(hit, 0)], hit)

    def escapes(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(N,) bool: each ray hits no face of the whole mesh (:meth:`RayCaster.escapes`)."""
        return self.whole.escapes(origins, directions)


def _check_rays(origins: np.ndarray, directions: np.ndarray) -> None:
    """Refuse ray arrays that are not (N, 3) alike: a launch Dr.Jit cannot size (rays of
    unequal counts, or none beside some) aborts the whole process."""
    o, d = np.shape(origins), np.shape(directions)
    if len(o) != 2 or o[1:] != (3,) or o != d:
        raise InputError(f"rays need origins and directions of one shape (N, 3), got {o} and {d}")
