"""The estimator's input types: a triangle mesh and calibrated views.

File formats live in ``harness``; these classes only hold and validate arrays,
so the estimator works on any data source. The result type is
:class:`estimator.model.estimate.Estimate`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .camera import Camera
from .errors import InputError


@dataclass(frozen=True)
class TriangleMesh:
    """A triangle mesh whose face order is the identity of each face.

    Attributes
    ----------
    vertices : (V, 3) float64, world space.
    faces : (F, 3) int64, vertex indices.
    """

    vertices: np.ndarray
    faces: np.ndarray

    def __post_init__(self):
        v = np.ascontiguousarray(self.vertices, dtype=np.float64)
        f = np.asarray(self.faces)
        if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
            raise InputError(f"mesh vertices must have shape (V, 3) with V > 0, got {v.shape}")
        if f.ndim != 2 or f.shape[0] == 0:
            raise InputError(f"mesh has no faces (faces shape {f.shape})")
        if f.shape[1] != 3:
            raise InputError(f"mesh must be made of triangles, got faces with {f.shape[1]} vertices")
        if not np.issubdtype(f.dtype, np.integer) or f.min() < 0 or f.max() >= v.shape[0]:
            raise InputError("mesh face indices must be integers in [0, V)")
        if not np.all(np.isfinite(v)):
            raise InputError("mesh vertices contain NaN or Inf")
        c = v[f]
        if not np.any(np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1) > 0):
            raise InputError(f"mesh has no face with non-zero area ({f.shape[0]} degenerate faces)")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", np.ascontiguousarray(f, dtype=np.int64))

    @property
    def num_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def corners(self) -> np.ndarray:
        """(F, 3, 3): the three vertex positions of each face."""
        return self.vertices[self.faces]

    @cached_property
    def centroids(self) -> np.ndarray:
        """(F, 3) face centroids; computed once per mesh (every view's rows and rays start
        there) and read-only."""
        centroids = self.corners.mean(axis=1)
        centroids.setflags(write=False)
        return centroids

    @cached_property
    def face_normals(self) -> np.ndarray:
        """(F, 3) unit geometric normals (counter-clockwise winding); computed once per mesh
        and read-only."""
        c = self.corners
        n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
        length = np.linalg.norm(n, axis=1, keepdims=True)
        normals = n / np.where(length > 0, length, 1.0)
        normals.setflags(write=False)
        return normals

    @cached_property
    def face_adjacency(self) -> np.ndarray:
        """(E, 2) int64 pairs of faces that share an edge (each pair once, lower index first);
        computed once per mesh (about 2 s at 1.3 M faces) and read-only."""
        f = self.faces
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        owner = np.tile(np.arange(len(f)), 3)
        order = np.lexsort((edges[:, 1], edges[:, 0]))
        edges, owner = edges[order], owner[order]
        same = np.all(edges[1:] == edges[:-1], axis=1)
        pairs = np.stack([owner[:-1][same], owner[1:][same]], axis=1)
        pairs = np.sort(pairs, axis=1)
        pairs = np.unique(pairs[pairs[:, 0] != pairs[:, 1]], axis=0)
        pairs.setflags(write=False)
        return pairs

    @property
    def bounds_centre(self) -> np.ndarray:
        """(3,) centre of the axis-aligned bounding box."""
        return 0.5 * (self.vertices.min(axis=0) + self.vertices.max(axis=0))

    @property
    def areas(self) -> np.ndarray:
        """(F,) face areas."""
        c = self.corners
        return 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)

    def degenerate_faces(self) -> tuple[np.ndarray, np.ndarray]:
        """((F,) bool, (F,) bool): faces of zero area (no normal: never observed), and faces
        whose three vertices an earlier face already uses (a repeat, which the rays hit in its
        place)."""
        flat = self.areas == 0
        ordered = np.sort(self.faces, axis=1).astype(np.int64)
        n = len(self.vertices)
        # one int64 key per face where it fits (a row-wise unique sorts 10x slower)
        keys = (ordered[:, 0] * n + ordered[:, 1]) * n + ordered[:, 2] if n < 2_000_000 else ordered
        _, first = np.unique(keys, axis=0, return_index=True)
        repeated = np.ones(self.num_faces, dtype=bool)
        repeated[first] = False
        return flat, repeated


@dataclass(frozen=True)
class View:
    """One calibrated HDR image.

    Attributes
    ----------
    name : str, identifies the image (e.g. its file path).
    camera : Camera.
    rgb : (H, W, 3) float32, linear Rec.709.
    alpha : (H, W) float32 pixel coverage by the object, or None (all 1).
    """

    name: str
    camera: Camera
    rgb: np.ndarray
    alpha: np.ndarray | None = None

    def __post_init__(self):
        rgb = np.asarray(self.rgb, dtype=np.float32)
        cam = self.camera
        if rgb.ndim != 3 or rgb.shape[2] != 3:
            raise InputError(f"view {self.name}: image must be (H, W, 3), got {rgb.shape}")
        if rgb.shape[:2] != (cam.height, cam.width):
            raise InputError(f"view {self.name}: image is {rgb.shape[1]}x{rgb.shape[0]} but the "
                             f"intrinsics say {cam.width}x{cam.height}")
        if not np.all(np.isfinite(rgb)):
            raise InputError(f"view {self.name}: image contains NaN or Inf pixels")
        object.__setattr__(self, "rgb", rgb)
        if self.alpha is not None:
            alpha = np.asarray(self.alpha, dtype=np.float32)
            if alpha.shape != rgb.shape[:2]:
                raise InputError(f"view {self.name}: alpha shape {alpha.shape} != image {rgb.shape[:2]}")
            if not np.all(np.isfinite(alpha)):
                raise InputError(f"view {self.name}: alpha contains NaN or Inf pixels")
            object.__setattr__(self, "alpha", alpha)


@dataclass(frozen=True)
class MultiViewData:
    """A mesh and its training views; ``test_views`` are held out (estimators must not use them)."""

    mesh: TriangleMesh
    views: list[View]
    test_views: list[View] = field(default_factory=list)

    def __post_init__(self):
        if len(self.views) == 0:
            raise InputError("the dataset has no frames (training views)")
