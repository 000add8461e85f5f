"""Per-face colour observations from calibrated views (the estimator's input rows)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.data import TriangleMesh, View
from ..core.errors import InputError
from ..core.reductions import group_quantile
from ..core.settings import Section
from ..rays.raycast import RayCaster


@dataclass
class ObservationConfig(Section):
    """Which pixels become observations (:func:`gather_observations`, :func:`estimator.pipeline.prepared.prepare`).

    Attributes
    ----------
    min_cos_view : keep an observation only when r . n = v . n exceeds this (0.5: within
        60 degrees of the normal). Far from the normal the Phong lobe around r is cut by the
        horizon, which the mirror term ignores.
    min_pixels : pixels a face must cover in a view to give an observation.
    pure_pixels : use only pixels covered by one face alone (the corner rays agree).
    min_coverage : a pixel is used only when the object covers at least this share of it
        (alpha); 0.999 keeps whole pixels and drops silhouette edges, whose colour mixes
        object and background.
    negative_tolerance : a pixel with a channel below -negative_tolerance x its view's
        99th-percentile value is dropped as an outlier (and counted): sensor and Monte Carlo
        noise on black stays within a percent of the bright level.
    """

    min_cos_view: float = 0.5
    min_pixels: int = 1
    pure_pixels: bool = True
    min_coverage: float = 0.999
    negative_tolerance: float = 0.01

    def check(self):
        return [
            (-1.0 <= self.min_cos_view < 1.0, "min_cos_view must lie in [-1, 1)"),
            (self.min_pixels >= 1, "min_pixels must be >= 1"),
            (0 < self.min_coverage <= 1, "min_coverage must lie in (0, 1]"),
            (self.negative_tolerance >= 0, "negative_tolerance must be >= 0"),
        ]


@dataclass(frozen=True)
class Observations:
    """One row per (face, view) pair where the face is seen.

    Attributes
    ----------
    face : (N,) int64 face index.
    rgb : (N, 3) float64 mean colour of the pixels whose centre ray hits the face.
    view_dir : (N, 3) unit direction from the face centroid to the camera.
    num_faces, num_views : int
    rejected : (num_views,) int64 object pixels dropped per view as negative beyond noise.
    view : (N,) int64 view of each row (None when unknown).
    """

    face: np.ndarray
    rgb: np.ndarray
    view_dir: np.ndarray
    num_faces: int
    num_views: int
    rejected: np.ndarray | None = None
    view: np.ndarray | None = None

    def subset(self, keep: np.ndarray) -> "Observations":
        """The rows where ``keep`` (N,) is true."""
        return Observations(self.face[keep], self.rgb[keep], self.view_dir[keep], self.num_faces, self.num_views,
                            self.rejected, None if self.view is None else self.view[keep])

    def observed_faces(self) -> np.ndarray:
        """(F,) bool: faces with at least one row."""
        return np.bincount(self.face, minlength=self.num_faces) > 0

    def median_color(self) -> np.ndarray:
        """(F, 3) per-face median colour over its rows (NaN for unseen faces)."""
        return group_quantile(self.face, self.rgb, self.num_faces, 0.5, interpolate=True)


# views of one object under one light differ in exposure level by what they see (a sunlit side
# against the sky-lit one: 10-100x), never by more than a camera's dynamic range (~14 stops);
# a view this far from the median one carries a wrong scale (or a corrupt file)
MAX_LEVEL_RATIO = 1e4


def _check_exposure_levels(views: list[View], levels: np.ndarray) -> None:
    """Refuse a view whose 99th-percentile object value lies more than MAX_LEVEL_RATIO from
    the median view's, naming it (one such view sank a whole estimate)."""
    lit = levels > 0
    if lit.sum() < 3:
        return
    median = float(np.median(levels[lit]))
    ratio = np.where(lit, levels / median, 1.0)
    bad = np.nonzero((ratio > MAX_LEVEL_RATIO) | (ratio < 1.0 / MAX_LEVEL_RATIO))[0]
    if len(bad):
        worst = int(bad[np.argmax(np.abs(np.log(ratio[bad])))])
        raise InputError(f"view {views[worst].name} is exposed {ratio[worst]:.3g} x the median view's level "
                         f"({len(bad)} view(s) beyond {MAX_LEVEL_RATIO:g} x either way, more than any camera's "
                         "dynamic range): a wrong scale or a corrupt image; fix it or drop it from the dataset")


def gather_observations(caster: RayCaster, views: list[View], min_pixels: int = ObservationConfig.min_pixels,
                        min_alpha: float = ObservationConfig.min_coverage,
                        pure_pixels: bool = ObservationConfig.pure_pixels,
                        negative_tolerance: float = ObservationConfig.negative_tolerance) -> Observations:
    """Face-ID buffers by primary rays through pixel centres, then per-face mean colours.

    Occlusion is exact: a pixel belongs to the first face its centre ray hits.
    With ``pure_pixels`` only pixels whose four corner rays hit the same face
    are used, so antialiased pixels that mix two faces' albedos do not bias
    small or thin regions. Pixels with coverage ``alpha < min_alpha``
    (silhouette edges) are skipped, and faces covered by fewer than
    ``min_pixels`` usable pixels in a view give no row. Pixels with a channel below
    ``-negative_tolerance`` x the view's 99th-percentile object value are not light
    (noise never goes that far below zero): they are dropped and counted per view.
    """
    mesh: TriangleMesh = caster.mesh
    f = mesh.num_faces
    centroids = mesh.centroids
    parts, rejected, levels = [], [], []
    buffers = caster.face_id_buffers([v.camera for v in views], pure=pure_pixels)
    for index, (view, ids) in enumerate(zip(views, buffers)):
        ids = ids.ravel()
        valid = ids >= 0
        if view.alpha is not None:
            valid &= view.alpha.ravel() >= min_alpha
        rgb = view.rgb.reshape(-1, 3)
        level = float(np.percentile(rgb[valid].max(axis=1), 99)) if valid.any() else 0.0
        levels.append(level)
        negative = valid & np.any(rgb < -negative_tolerance * max(level, 1e-30), axis=1)
        rejected.append(int(negative.sum()))
        valid &= ~negative
        ids = ids[valid]
        rgb = rgb[valid].astype(np.float64)
        counts = np.bincount(ids, minlength=f)
        sums = np.stack([np.bincount(ids, rgb[:, c], minlength=f) for c in range(3)], axis=1)
        faces = np.nonzero(counts >= max(min_pixels, 1))[0]
        to_cam = view.camera.center[None] - centroids[faces]
        to_cam /= np.linalg.norm(to_cam, axis=1, keepdims=True)
        parts.append((faces, sums[faces] / counts[faces, None], to_cam, np.full(len(faces), index)))
    clear = [view.name for view in views if view.alpha is not None and not np.any(view.alpha >= min_alpha)]
    if clear:
        raise InputError(f"{len(clear)} view(s) are fully transparent (alpha below {min_alpha} everywhere): "
                         f"{', '.join(clear[:5])}{' ...' if len(clear) > 5 else ''}; check their alpha channel "
                         "or drop them from the dataset")
    blind = [view.name for view, part in zip(views, parts) if len(part[0]) == 0]
    if len(blind) == len(views):
        raise InputError("no camera sees any face of the mesh: check the poses (OpenGL c2w) and the mesh")
    if blind:
        raise InputError(f"{len(blind)} camera(s) see none of the mesh: {', '.join(blind[:5])}"
                         f"{' ...' if len(blind) > 5 else ''}; check their poses or drop them from the dataset")
    _check_exposure_levels(views, np.array(levels))
    face, rgb, view_dir, view_index = (np.concatenate(p) for p in zip(*parts))
    return Observations(face.astype(np.int64), rgb, view_dir, f, len(views), np.array(rejected, dtype=np.int64),
                        view_index.astype(np.int64))
