"""Per-face colour observations from calibrated views (the estimator's input rows)."""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from ..core.data import TriangleMesh, View
from ..core.errors import InputError
from ..core.reductions import group_quantile
from ..core.settings import Section
from ..rays.raycast import RayCaster
from ..solvers import robust
from .footprints import Footprints, footprint_radiance, pixel_shares, radiance_error, unmixed_rows


@dataclass
class ObservationConfig(Section):
    """Which pixels become observations (:func:`gather_observations`, :func:`estimator.pipeline.prepared.prepare`).

    Attributes
    ----------
    min_cos_view : keep an observation only when r . n = v . n exceeds this (0.5: within
        60 degrees of the normal). Far from the normal the Phong lobe around r is cut by the
        horizon, which the mirror term ignores.
    min_pixels : pixels a face must cover in a view to give an observation.
    pure_pixels : observe a face through the pixels it alone covers (the corner rays agree).
        Where such pixels resolve under half of the faces that pixel centres hit (faces
        smaller than a pixel, as on a dense scan), the faces they miss are observed through
        the pixels they cover, unmixed from their neighbours (``subpixel_samples``). Off:
        every face through its pixel centres.
    subpixel_samples : on a mesh denser than its photos, each usable pixel is an equation in
        the faces that this many x this many sub-pixel rays hit, weighted by the share of
        rays each takes (the box filter of a render or a sensor), and a face's row in a view
        is its radiance solved from every view plus the view-dependent residual of its
        pixels (:mod:`estimator.pipeline.footprints`). 1: a face's row is the mean colour
        of the pixels whose centre ray hits it, which mixes its neighbours' colours.
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
    subpixel_samples: int = 4

    def check(self):
        return [
            (-1.0 <= self.min_cos_view < 1.0, "min_cos_view must lie in [-1, 1)"),
            (self.min_pixels >= 1, "min_pixels must be >= 1"),
            (0 < self.min_coverage <= 1, "min_coverage must lie in (0, 1]"),
            (self.negative_tolerance >= 0, "negative_tolerance must be >= 0"),
            (self.subpixel_samples >= 1, "subpixel_samples must be >= 1"),
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
    unresolved : (num_faces,) bool, faces observed through the pixels they cover, unmixed
        from their neighbours (or through their pixel centres), because pure pixels resolve
        too few faces (:func:`gather_observations`); None when no face is, or without
        ``pure_pixels``.
    footprint_pixels : the mean pixel area a row of an unresolved face covers in its view
        (the share of sub-pixel rays it takes, summed over its pixels; with one sub-pixel
        sample, its pixel centres); None when no face is unresolved.
    rowless_views : (K,) int64 views that show the mesh but give no row: no face covers
        ``min_pixels`` of their pixels whole, the images resolve the faces elsewhere, and no
        thin face is unmixed from their pixels (:func:`gather_observations`; empty for
        observations made otherwise, e.g. merged into clusters).
    radiance_se : (num_faces, 3) float64 the standard error of each unresolved or thin face's
        radiance unmixed from the pixels it shares (:func:`.footprints.radiance_error`), 0 for the other
        faces; every row of such a face holds that one radiance, so the albedos' standard
        errors add it (:func:`estimator.diagnostics.trust.albedo_precision`). None: no face was
        unmixed.
    thin : (num_faces,) bool, on a mesh the pure pixels resolve, the faces they miss (thin or
        small faces: a teapot's spout and rim) observed through their unmixed footprints as
        ``unresolved`` faces are on a dense mesh; None when no face is. Their radiance is
        noisier than a resolved face's (``radiance_se``), so a method may keep them out of
        what the faces determine together (the light) and solve their albedos under it.
    black_views : (K,) int64 views that show the mesh black (no pixel on it above zero): a
        diffuse face's colour is the same from every view, so zeros where other views see it
        lit are a failed capture, not light, and the view gives no row; a face unlit from
        every view has no light to estimate from either way (:func:`gather_observations`;
        empty for observations made otherwise).
    """

    face: np.ndarray
    rgb: np.ndarray
    view_dir: np.ndarray
    num_faces: int
    num_views: int
    rejected: np.ndarray | None = None
    view: np.ndarray | None = None
    unresolved: np.ndarray | None = None
    footprint_pixels: float | None = None
    rowless_views: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    black_views: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    radiance_se: np.ndarray | None = None
    thin: np.ndarray | None = None

    @cached_property
    def face_levels(self) -> np.ndarray:
        """(num_faces,) the norm of each face's median colour over its rows
        (:func:`estimator.solvers.robust.face_levels`): every robust solve on these rows clips
        glints to it, so it is computed once per set of rows (a new set, e.g. the colours less a
        coat's reflection, is a new ``Observations``)."""
        return robust.face_levels(self.face, self.rgb, self.num_faces)

    def subset(self, keep: np.ndarray) -> "Observations":
        """The rows where ``keep`` (N,) is true."""
        return Observations(self.face[keep], self.rgb[keep], self.view_dir[keep], self.num_faces, self.num_views,
                            self.rejected, None if self.view is None else self.view[keep], self.unresolved,
                            self.footprint_pixels, self.rowless_views, self.black_views, self.radiance_se,
                            self.thin)

    def merged(self, cluster: np.ndarray, count: int, weight: np.ndarray) -> "Observations":
        """One row per (cluster, view) pair: the ``weight``-weighted mean colour and view
        direction of the rows of the cluster's faces in that view, what one face covering the
        cluster would show. ``cluster`` (num_faces,) gives each face's cluster in [0, count)
        (-1: its rows are left out); ``weight`` (num_faces,) each face's weight (its area)."""
        if self.view is None:
            raise InputError("observations without their views cannot be merged per view")
        keep = cluster[self.face] >= 0
        key = cluster[self.face[keep]] * self.num_views + self.view[keep]
        rows, inverse = np.unique(key, return_inverse=True)
        w = weight[self.face[keep]]
        total = np.bincount(inverse, w, minlength=len(rows))

        def mean(values):
            return np.stack([np.bincount(inverse, w * values[keep, k], minlength=len(rows)) for k in range(3)],
                            axis=1) / total[:, None]

        direction = mean(self.view_dir)
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        return Observations(rows // self.num_views, mean(self.rgb), direction, count, self.num_views, self.rejected,
                            rows % self.num_views)

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


def _face_means(ids: np.ndarray, valid: np.ndarray, rgb: np.ndarray, num_faces: int, min_pixels: int,
                skip: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The faces (K,) int64 covered by at least ``min_pixels`` of the ``valid`` pixels in the
    face-ID buffer ``ids`` (P,) (and not in ``skip`` (F,) bool), with the mean colour (K, 3)
    of ``rgb`` (P, 3) over those pixels and their number (K,)."""
    keep = np.nonzero(valid & (ids >= 0))[0]
    ids = ids[keep]
    counts = np.bincount(ids, minlength=num_faces)
    # one channel's pixels at a time (bincount takes its weights in float64 itself): 3x faster
    # than indexing the (P, 3) colours and converting them first
    sums = np.stack([np.bincount(ids, rgb[keep, c], minlength=num_faces) for c in range(3)], axis=1)
    use = counts >= max(min_pixels, 1)
    if skip is not None:
        use &= ~skip
    faces = np.nonzero(use)[0]
    return faces, sums[faces] / counts[faces, None], counts[faces]


def _unmixed_rows(caster: RayCaster, views: list[View], usable: list[np.ndarray], centre_ids: list[np.ndarray],
                  footprint: np.ndarray, samples: int,
                  min_pixels: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rows of the ``footprint`` faces (F,) bool, unmixed from every usable pixel
    (``usable``: (H*W,) bool per view) as equations in the faces its ``samples`` x ``samples``
    sub-pixel rays hit (:mod:`.footprints`): (K,) faces, views, (K, 3) colours, (K,) the
    pixel area each row's face covers in its view, and (F, 3) the standard error of every
    face's footprint radiance (:func:`.footprints.radiance_error`). A (face, view) pair gives a row where the
    centre rays of ``min_pixels`` usable pixels hit the face (as without sub-pixel rays) or
    where the face covers at least half of ``min_pixels`` pixels' area. A pixel whose sub-pixel
    rays miss the mesh (a silhouette) is left out."""
    f = caster.mesh.num_faces
    shares, colours, owner, centres = [], [], [], []
    for index, (view, valid, ids) in enumerate(zip(views, usable, centre_ids)):
        pixels = np.nonzero(valid)[0]
        sub = caster.subpixel_faces(view.camera, samples, pixels)
        whole = np.all(sub >= 0, axis=1)
        shares.append(pixel_shares(sub[whole], f))
        colours.append(view.rgb.reshape(-1, 3)[pixels[whole]].astype(np.float64))
        owner.append(np.full(int(whole.sum()), index, dtype=np.int64))
        hits, counts = np.unique(ids.ravel()[pixels[whole]], return_counts=True)
        centres.append(index * f + hits[counts >= min_pixels])
    fp = Footprints(sp.vstack(shares).tocsr(), np.concatenate(colours), np.concatenate(owner))
    radiance, _ = footprint_radiance(fp, caster.mesh.face_adjacency)
    face, view, rgb, share = unmixed_rows(fp, radiance)
    keep = footprint[face] & ((share >= 0.5 * min_pixels) | np.isin(view * f + face, np.concatenate(centres)))
    return face[keep], view[keep], rgb[keep], share[keep], radiance_error(fp, radiance)


def _around(faces: np.ndarray, mesh: TriangleMesh, usable: list[np.ndarray],
            centre_ids: list[np.ndarray]) -> list[np.ndarray]:
    """Per view, the ``usable`` pixels (H*W,) bool whose centre ray hits one of ``faces`` (F,)
    bool or a face that shares an edge with one: the pixels about those faces, with their
    neighbours' own pixels that settle the neighbours' radiance. On a mesh the images
    resolve, the thin faces are unmixed from these alone (sub-pixel rays over every pixel cost
    a second on a 5k-face teapot); a pixel that covers a thin face but whose centre hits a
    face beyond them (one sharing only a vertex, or a nearer part of the object) is left out,
    and the face is unmixed from the others."""
    near = faces.copy()
    pairs = mesh.face_adjacency
    near[pairs[faces[pairs[:, 1]], 0]] = True
    near[pairs[faces[pairs[:, 0]], 1]] = True
    return [valid & near[np.maximum(ids.ravel(), 0)] for valid, ids in zip(usable, centre_ids)]


def check_transparent(views: list[View], min_alpha: float) -> None:
    """Refuse (:class:`InputError`, naming them) views whose alpha is below ``min_alpha``
    everywhere: they show no pixel to estimate from. Checked before anything is traced (the
    pose refinement's estimates too)."""
    clear = [view.name for view in views if view.alpha is not None and not np.any(view.alpha >= min_alpha)]
    if clear:
        raise InputError(f"{len(clear)} view(s) are fully transparent (alpha below {min_alpha} everywhere): "
                         f"{', '.join(clear[:5])}{' ...' if len(clear) > 5 else ''}: the object is outside their "
                         "frame (check the mesh's position and scale against the cameras) or their alpha channel "
                         "is empty (check it, or drop them from the dataset)")


def gather_observations(caster: RayCaster, views: list[View], min_pixels: int = ObservationConfig.min_pixels,
                        min_alpha: float = ObservationConfig.min_coverage,
                        pure_pixels: bool = ObservationConfig.pure_pixels,
                        negative_tolerance: float = ObservationConfig.negative_tolerance,
                        subpixel_samples: int = ObservationConfig.subpixel_samples,
                        max_pixels: int | None = None) -> Observations:
    """Face-ID buffers by primary rays through pixel centres, then per-face mean colours.

    Occlusion is exact: a pixel belongs to the first face its centre ray hits.
    With ``pure_pixels`` a face is observed through the pixels whose four corner rays
    hit it alone, so antialiased pixels that mix two faces' albedos do not bias small or
    thin regions. When such pixels cover under half of the faces that pixel centres hit,
    the images resolve no face (a mesh denser than its photos): the faces without a pure
    pixel are then observed through the pixels they cover, each pixel an equation in the
    faces its ``subpixel_samples`` x ``subpixel_samples`` rays hit (:func:`_unmixed_rows`;
    with one sample, the mean of the pixels whose centre ray hits the face). Where they
    resolve most faces, the faces they miss (thin or small faces of a coarser mesh) are
    observed through their unmixed pixels too (``Observations.thin``); without sub-pixel
    samples they stay unobserved rather than take a neighbour's colour. A
    view in which no face covers ``min_pixels`` pixels whole (a camera far from the object
    among nearer ones) gives no row: it is named (``rowless_views``), not refused. The
    pixels' equations are held in memory: beyond ``max_pixels`` pixels to unmix (None: no
    bound) the faces of a dense mesh are observed through their pixel centres instead, and
    the thin faces of a resolved one not at all.
    Pixels with coverage ``alpha < min_alpha``
    (silhouette edges) are skipped, and faces covered by fewer than
    ``min_pixels`` usable pixels in a view give no row. Pixels with a channel below
    ``-negative_tolerance`` x the view's 99th-percentile object value are not light
    (noise never goes that far below zero): they are dropped and counted per view.
    """
    check_transparent(views, min_alpha)
    mesh: TriangleMesh = caster.mesh
    f = mesh.num_faces
    cameras = [v.camera for v in views]
    pure_ids = caster.face_id_buffers(cameras, pure=True) if pure_pixels else [None] * len(views)
    centre_ids = caster.face_id_buffers(cameras)   # the caster's kept buffers: traced once
    usable, rejected, levels, on_mesh, black = [], [], [], [], []
    for view, ids in zip(views, centre_ids):
        valid = ids.ravel() >= 0
        if view.alpha is not None:
            valid &= view.alpha.ravel() >= min_alpha
        rgb = view.rgb.reshape(-1, 3)
        # channel extremes as element-wise maxima and minima: numpy reduces an axis of 3 ten times slower
        peak = np.maximum(np.maximum(rgb[:, 0], rgb[:, 1]), rgb[:, 2])
        level = float(np.percentile(peak[valid], 99)) if valid.any() else 0.0
        levels.append(level)
        floor = np.minimum(np.minimum(rgb[:, 0], rgb[:, 1]), rgb[:, 2])
        negative = valid & (floor < -negative_tolerance * max(level, 1e-30))
        rejected.append(int(negative.sum()))
        # a view black on the mesh, no pixel above zero (a failed capture): a diffuse face's colour
        # is the same from every view, so its zeros are no observation of a face lit elsewhere
        # (mostly below zero, it is a sign error, refused below)
        kept = valid & ~negative
        black.append(bool(kept.any()) and rejected[-1] <= kept.sum() and not np.any(peak[kept] > 0))
        usable.append(kept & (not black[-1]))
        on_mesh.append(bool(valid.any()))
    # the pure pixels' rows; where they resolve under half of the faces a pixel centre hits
    # (faces smaller than a pixel: a dense scan), the other faces' rows through their centres
    pure_rows = [None if p is None else _face_means(p.ravel(), valid, view.rgb.reshape(-1, 3), f, min_pixels)
                 for p, valid, view in zip(pure_ids, usable, views)]
    covered = np.zeros(f, dtype=bool)
    hit = np.zeros(f, dtype=bool)
    for row, ids, valid in zip(pure_rows, centre_ids, usable):
        hit[ids.ravel()[valid]] = True
        if row is not None:
            covered[row[0]] = True
    resolves = pure_pixels and 2 * covered.sum() >= hit.sum()
    # on a mesh the images resolve, the faces no pure pixel covers (thin faces) are unmixed
    # from the pixels about them, or not observed where nothing unmixes them: a pixel centre's
    # colour would mix a neighbour's albedo into theirs
    unmixed_pixels = _around(hit & ~covered, mesh, usable, centre_ids) if resolves else usable
    unmixing = pure_pixels and subpixel_samples > 1 and (max_pixels is None
                                                         or sum(int(p.sum()) for p in unmixed_pixels) <= max_pixels)
    footprint = ~covered if not resolves else hit & ~covered if unmixing else np.zeros(f, dtype=bool)
    parts, footprint_pixels = [], 0
    unmixed = _unmixed_rows(caster, views, unmixed_pixels, centre_ids, footprint, subpixel_samples, min_pixels) \
        if unmixing and footprint.any() else None
    for index, (view, ids, valid, row) in enumerate(zip(views, centre_ids, usable, pure_rows)):
        if footprint.any():   # the footprint rows, and the pure rows (none without pure_pixels)
            if unmixed is None:
                faces, means, pixels = _face_means(ids.ravel(), valid, view.rgb.reshape(-1, 3), f, min_pixels,
                                                   skip=~footprint)
            else:
                mine = unmixed[1] == index
                faces, means, pixels = unmixed[0][mine], unmixed[2][mine], unmixed[3][mine]
            footprint_pixels += float(pixels.sum())
            if row is not None:
                order = np.argsort(np.concatenate([row[0], faces]), kind="stable")
                faces, means = np.concatenate([row[0], faces])[order], np.concatenate([row[1], means])[order]
        else:
            faces, means, _ = row
        to_cam = view.camera.center[None] - mesh.centroids[faces]
        to_cam /= np.linalg.norm(to_cam, axis=1, keepdims=True)
        parts.append((faces, means, to_cam, np.full(len(faces), index)))
    # a view whose pixels on the mesh are mostly below zero, the rest exactly zero, is as dark
    dark = [view.name for view, valid, seen, n, blank in zip(views, usable, on_mesh, rejected, black) if seen
            and not blank and (not valid.any() or (n > valid.sum() and not np.any(view.rgb.reshape(-1, 3)[valid] > 0)))]
    if dark:
        raise InputError(f"{len(dark)} view(s) show the mesh but every pixel on it has a channel below zero "
                         f"(or is black): {', '.join(dark[:5])}{' ...' if len(dark) > 5 else ''}; check their black "
                         "level and sign (the images must be linear radiance) or drop them from the dataset")
    black = np.nonzero(black)[0]
    empty = [index for index, part in enumerate(parts) if len(part[0]) == 0 and index not in black]
    if len(empty) + len(black) == len(views) and hit.any() and len(black) < sum(on_mesh):
        remedy = "lower min_pixels" if min_pixels > 1 else (
            "none of their pixels yields an observation (faces far smaller than the pixels, or seen only at the "
            "silhouette); check the mesh against the images")
        raise InputError(f"no face covers min_pixels={min_pixels} pixels in any view, although pixel centres hit "
                         f"{int(hit.sum())} faces: {remedy}")
    if len(empty) == len(views):
        raise InputError("no camera sees any face of the mesh: check the poses (OpenGL c2w) and the mesh")
    blind = [views[index].name for index in empty if not usable[index].any()]
    if blind:
        raise InputError(f"{len(blind)} camera(s) see none of the mesh: {', '.join(blind[:5])}"
                         f"{' ...' if len(blind) > 5 else ''}: under their poses no pixel centre that can observe the "
                         "mesh hits it (outside the frame, or off the object their alpha covers); check their poses "
                         "(an object only a few pixels across is too small for the pose refinement to align) or drop "
                         "them from the dataset")
    # the other empty views show the mesh, but no face covers min_pixels of their pixels whole (a
    # camera far from the object among nearer ones): named in rowless_views, not refused
    if len(black) + len(empty) == len(views):
        raise InputError("every view shows the mesh black (no pixel on it above zero): the images hold no light; "
                         "check their exposure and black level")
    _check_exposure_levels(views, np.array(levels))
    face, rgb, view_dir, view_index = (np.concatenate(p) for p in zip(*parts))
    unresolved = footprint & (np.bincount(face, minlength=f) > 0)
    dense = pure_pixels and unresolved.any() and not resolves
    thin = unresolved if resolves and unresolved.any() else None
    radiance_se = None
    if unresolved.any() and unmixed is not None:   # the unmixed faces' radiance error; the others' rows: own pixels
        radiance_se = np.where(unresolved[:, None], unmixed[4], 0.0)
    return Observations(face.astype(np.int64), rgb, view_dir, f, len(views), np.array(rejected, dtype=np.int64),
                        view_index.astype(np.int64), unresolved if dense else None,
                        footprint_pixels / max(int(unresolved[face].sum()), 1) if dense else None,
                        np.array(empty, dtype=np.int64), black.astype(np.int64), radiance_se, thin)
