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

# a face is flat (it has no normal) when its doubled area, |e1 x e2|, is within the rounding of
# its vertex coordinates: mesh files commonly store them as float32, spaced |v| 2^-23 apart at a
# coordinate of size |v|, so the cross product of edges of length L carries an error of about
# |v| L 2^-23; four such spacings. A collinear face written in float32 has an area of that order
# and a normal that is rounding noise.
FLAT_TOLERANCE = 4 * 2.0 ** -23


def _flat(corners: np.ndarray) -> np.ndarray:
    """(F,) bool faces of ``corners`` (F, 3, 3) whose doubled area is within
    :data:`FLAT_TOLERANCE` of the rounding of their coordinates (the tolerance scales with the
    coordinates' size: far from the origin, float32 spaces them wider)."""
    doubled = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    edge = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    return doubled <= FLAT_TOLERANCE * np.abs(corners).max(axis=(1, 2)) * edge


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
        # areas and normals square products of two coordinate differences: past ~1e77 they overflow
        if float(np.abs(v).max()) > 1e75:
            raise InputError(f"mesh vertex coordinates reach {float(np.abs(v).max()):.3g}: their face areas overflow "
                             "double precision; rescale the mesh")
        flat = _flat(v[f])
        if np.all(flat):
            raise InputError(f"mesh has no face with non-zero area ({f.shape[0]} degenerate faces, their area zero "
                             "or within the rounding of their coordinates)")
        flat.setflags(write=False)
        self.__dict__["flat"] = flat   # :attr:`flat`'s cache: the check has computed it
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
        normals = np.where(self.flat[:, None], 0.0, n / np.where(length > 0, length, 1.0))
        normals.setflags(write=False)
        return normals

    @cached_property
    def flat(self) -> np.ndarray:
        """(F,) bool faces without a normal: a doubled area within :data:`FLAT_TOLERANCE` of the
        rounding of their coordinates (zero area, or collinear corners written in float32);
        computed once per mesh, by the mesh's own check when it is made, and read-only."""
        flat = _flat(self.corners)
        flat.setflags(write=False)
        return flat

    @cached_property
    def welded_faces(self) -> np.ndarray:
        """(F, 3) int64 each face's vertex indices with the vertices at one position made one: an
        unwelded mesh (every face its own three vertices, as STL and many exports write it)
        shares no index between neighbouring faces but shares their positions. Computed once
        per mesh and read-only."""
        v = self.vertices
        order = np.lexsort(v.T[::-1])   # positions sorted; a row-wise np.unique is 3x slower
        ordered = v[order]
        first = np.concatenate([[True], np.any(ordered[1:] != ordered[:-1], axis=1)])
        position = np.empty(len(v), dtype=np.int64)
        position[order] = np.cumsum(first) - 1
        welded = position[self.faces]
        welded.setflags(write=False)
        return welded

    @property
    def face_adjacency(self) -> np.ndarray:
        """(E, 2) int64 pairs of faces that share an edge, two corners at the same positions
        (:attr:`welded_faces`), each pair once, lower index first; computed once per mesh
        (about 2 s at 1.3 M faces) and read-only."""
        return self._shared_edges[0]

    def winding_conflicts(self) -> np.ndarray:
        """(E,) bool over :attr:`face_adjacency`: the two faces run a shared edge in the same
        direction, so one of them is wound the other way (consistent neighbours run it in
        opposite directions). An edge of more than two faces (non-manifold, or a double-sided
        sheet whose coincident faces are wound apart on purpose) gives no verdict."""
        return self._shared_edges[1]

    @cached_property
    def _shared_edges(self) -> tuple[np.ndarray, np.ndarray]:
        """:attr:`face_adjacency` and :meth:`winding_conflicts` from one sort of the faces'
        directed edges by their corners; both read-only."""
        f = self.welded_faces
        start, end = f.T.ravel(), f[:, [1, 2, 0]].T.ravel()   # each face's edges, in winding order
        owner = np.tile(np.arange(len(f)), 3)
        low, high = np.minimum(start, end), np.maximum(start, end)
        order = np.lexsort((high, low))
        low, high, owner, forward = low[order], high[order], owner[order], (start < end)[order]
        starts = np.concatenate([[True], (low[1:] != low[:-1]) | (high[1:] != high[:-1])])
        edge = np.cumsum(starts) - 1
        manifold = np.bincount(edge)[edge] == 2   # per entry: its edge joins exactly two faces
        same = ~starts[1:] & (owner[1:] != owner[:-1])
        pairs = np.sort(np.stack([owner[:-1][same], owner[1:][same]], axis=1), axis=1)
        conflict = ((forward[:-1] == forward[1:]) & manifold[1:])[same]
        adjacency, row = np.unique(pairs.reshape(-1, 2), axis=0, return_inverse=True)
        conflicts = np.zeros(len(adjacency), dtype=bool)
        conflicts[row.ravel()[conflict]] = True
        adjacency = adjacency.astype(np.int64)
        for array in (adjacency, conflicts):
            array.setflags(write=False)
        return adjacency, conflicts

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
        """((F,) bool, (F,) bool): faces without a normal (:attr:`flat`: never observed), and
        faces whose three corners an earlier face already has (a repeat, which the rays hit in
        its place; through the same vertices or copies of them, :attr:`welded_faces`)."""
        flat = self.flat
        ordered = np.sort(self.welded_faces, axis=1)
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
        if not isinstance(cam, Camera):
            raise InputError(f"view {self.name}: camera must be a Camera, got {type(cam).__name__}")
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
            # a coverage: a share of the pixel in [0, 1] (half-float files overshoot 1 by a spacing)
            if alpha.size and (alpha.min() < -0.01 or alpha.max() > 1.01):
                raise InputError(f"view {self.name}: alpha must be a coverage in [0, 1], got values from "
                                 f"{alpha.min():.3g} to {alpha.max():.3g}")
            object.__setattr__(self, "alpha", alpha)


@dataclass(frozen=True)
class MultiViewData:
    """A mesh and its training views; ``test_views`` are held out (estimators must not use them)."""

    mesh: TriangleMesh
    views: list[View]
    test_views: list[View] = field(default_factory=list)

    def __post_init__(self):
        if not isinstance(self.mesh, TriangleMesh):
            raise InputError(f"MultiViewData.mesh must be a TriangleMesh, got {type(self.mesh).__name__}")
        for name in ("views", "test_views"):
            views = getattr(self, name)
            if not isinstance(views, (list, tuple)) or not all(isinstance(v, View) for v in views):
                raise InputError(f"MultiViewData.{name} must be a list of View, got {type(views).__name__}")
        if len(self.views) == 0:
            raise InputError("the dataset has no frames (training views)")
        # a view's name keys its per-view results (outline offsets, gains, poses): two alike would merge
        names = [v.name for v in self.views]
        if len(set(names)) != len(names):
            twice = sorted({n for n in names if names.count(n) > 1})
            raise InputError(f"training views must have distinct names; repeated: {', '.join(map(repr, twice[:5]))}")
