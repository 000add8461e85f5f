"""Per-view pose refinement: small rotation and translation updates of each training camera
that align its image with the image the estimate predicts for it, the mesh held fixed.

The surface points seen through a view's covered pixels carry the predicted radiance
(:class:`estimator.model.forward.Predictor`, at the current pose). A pose update moves where those
points project; the update minimises the difference between the observed image sampled
there and the prediction (direct photometric alignment, Lucas-Kanade on the rigid motion):

    E(xi) = sum_p rho( I(pi(T(xi)^-1 P_p)) - r_p ),

with P_p a point in the camera frame, T(xi) applied on the right of the camera-to-world
matrix (:func:`rigid_update`: ``omega`` turns the camera about the centre of the surface it
sees, ``t`` moves it in its own frame), rho the Cauchy loss and I the observed image. Gauss-Newton steps with
Levenberg-Marquardt damping run from coarse to fine: both images are blurred by a Gaussian
of each scale in turn, so an error of several pixels lies inside the first scale's basin.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.ndimage import gaussian_filter

from ..core.camera import Camera
from ..core.data import MultiViewData, View
from ..core.errors import InputError
from ..core.settings import Section
from ..model.estimate import Estimate
from ..model.forward import Predictor
from ..rays.raycast import RayCaster
from ..solvers.robust import TUNING, irls_weights, robust_scale

# Gaussian sigmas (pixels) of the coarse-to-fine levels; 2 degrees at a 256-pixel, 40-degree
# view is about 13 pixels, inside the first level's basin
POSE_SCALES = (8.0, 4.0, 2.0, 1.0)
SILHOUETTE_SCALES = (16.0, 8.0, 4.0, 2.0)   # the first, silhouette-only move
POSE_ROUNDS = 2          # alignment rounds against held-out estimates
POSE_MAX_ROUNDS = 20     # the most a user may ask for
POSE_STEPS = 10          # Gauss-Newton steps per level
POSE_MAX_DEGREES = 10.0  # a correction beyond this turn, or beyond POSE_MAX_SHIFT x the distance to
POSE_MAX_SHIFT = 0.25    # the mesh, is a divergence (against a poor estimate), not a calibration error
POSE_MIN_GAIN = 1e-4     # a level stops when a step lowers the cost by less than this share,
POSE_MIN_MOVE = 0.01     # or moves no point by more than this share of the level's Gaussian sigma: a blurred level
                         # places points to a fraction of its sigma only (0.01 px at the finest, far below what a
                         # pose is judged at)
POSE_MIN_VIEWS = 3       # a held-out estimate from fewer views is too poor to align with
POSE_LEVEL_POINTS = 10   # a blurred level with fewer sampled points is skipped
# points sampled per level at most: six unknowns are pinned by a few thousand pixels (the
# pose's standard error falls as 1 / sqrt(points)), and a denser grid only costs time
POSE_MAX_POINTS = 4096
POSE_MIN_POINTS = 200    # a view with fewer covered pixels keeps its pose
# pixels between a view's alpha outline and the mesh's under its camera (outline_offsets) beyond
# which the pose is wrong: correct poses measured 0.01-0.3 px on every shipped scene (edge pixels
# split by the 0.5 threshold), a 0.5 deg jitter several px
POSE_OUTLINE_TOLERANCE = 1.0
# bytes of observed levels kept across the rounds, all views together (ObservedLevels): every
# level of 24 views at 256² (7 MiB a view) fits; larger images keep their first levels and blur
# the others again each round, so the memory does not grow with the images' size
POSE_KEPT_BYTES = 256 * 2**20


@dataclass
class PoseConfig(Section):
    """Per-view pose refinement before the solve (:func:`refine_poses`).

    Attributes
    ----------
    pose_rounds : rounds of refinement (0 trusts the cameras): each camera first moves so
        the mesh's silhouette matches the view's alpha, then each round the views are split
        into ``pose_folds`` interleaved groups and each group is aligned with the image an
        estimate from the other groups predicts.
    pose_folds : view groups per round.
    auto_pose : with ``pose_rounds`` 0, the poses are refined anyway (:data:`POSE_ROUNDS`
        rounds) when any view's alpha outline lies more than this many pixels from the
        mesh's outline under its camera (:func:`outline_offsets`; 0: never).
    """

    pose_rounds: int = 0
    pose_folds: int = 4
    auto_pose: float = POSE_OUTLINE_TOLERANCE

    def check(self):
        return [
            (0 <= self.pose_rounds <= POSE_MAX_ROUNDS, f"pose_rounds must lie in [0, {POSE_MAX_ROUNDS}] (each round "
             "is pose_folds held-out estimates; the rounds end early once one moves no view)"),
            (self.auto_pose >= 0, "auto_pose must be >= 0 (0: never)"),
            (self.pose_folds >= 2, "pose_folds must be >= 2 (a view group is aligned against an estimate "
                                   "from the other views)"),
        ]


def skew(v: np.ndarray) -> np.ndarray:
    """(3,) -> (3, 3) cross-product matrix, skew(a) @ b = a x b."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rigid_update(delta: np.ndarray, pivot: np.ndarray) -> np.ndarray:
    """(4, 4) camera-frame motion of ``delta`` = (omega (3,) radians, Rodrigues; t (3,)): a
    turn by R(omega) about ``pivot`` (3,), then a shift by t: [R, t + pivot - R pivot; 0 1]."""
    omega, t = np.asarray(delta[:3], dtype=np.float64), np.asarray(delta[3:], dtype=np.float64)
    angle = np.linalg.norm(omega)
    k = skew(omega / angle) if angle > 0 else np.zeros((3, 3))
    m = np.eye(4)
    m[:3, :3] = np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)
    m[:3, 3] = t + pivot - m[:3, :3] @ pivot
    return m


def projection_jacobian(points: np.ndarray, pivot: np.ndarray, fx: float, fy: float) -> np.ndarray:
    """d(pixel)/d(delta) at delta = 0 for camera-frame points (OpenGL: looks down -Z) under
    :func:`rigid_update` about ``pivot`` (3,).

    Parameters
    ----------
    points : (N, 3) camera-frame positions (z < 0 in front).

    Returns
    -------
    (N, 2, 6): columns omega (radians) then t (world units), rows (column, row) pixels.
    """
    x, y, depth = points[:, 0], points[:, 1], -points[:, 2]
    # d(column)/dP' = (ux, 0, uz) and d(row)/dP' = (0, vy, vz)
    ux, uz = fx / depth, fx * x / depth ** 2
    vy, vz = -fy / depth, -fy * y / depth ** 2
    # P' = R^T (P - pivot - t) + pivot: dP'/domega = skew(P - pivot), dP'/dt = -I, and
    # g^T skew(q) = (g x q)^T for any gradient row g (the cross products written out: the
    # zero entries of the two rows drop their terms)
    qx, qy, qz = (points - pivot).T
    out = np.zeros((len(points), 2, 6))
    out[:, 0, 0], out[:, 0, 1], out[:, 0, 2] = -uz * qy, uz * qx - ux * qz, ux * qy
    out[:, 0, 3], out[:, 0, 5] = -ux, -uz
    out[:, 1, 0], out[:, 1, 1], out[:, 1, 2] = vy * qz - vz * qy, vz * qx, -vy * qx
    out[:, 1, 4], out[:, 1, 5] = -vy, -vz
    return out


def _sample(image: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Bilinear samples (N, C) of ``image`` (H, W, C) at continuous pixel coordinates (N, 2)
    (pixel centres at half-integers; clamped at the border)."""
    height, width = image.shape[:2]
    x = np.clip(xy[:, 0] - 0.5, 0.0, width - 1.0)
    y = np.clip(xy[:, 1] - 0.5, 0.0, height - 1.0)
    x0 = np.minimum(x.astype(np.int64), max(width - 2, 0))
    y0 = np.minimum(y.astype(np.int64), max(height - 2, 0))
    x1, y1 = np.minimum(x0 + 1, width - 1), np.minimum(y0 + 1, height - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    flat = image.reshape(height * width, -1)   # take on flat rows: 2.5x faster than 2-D fancy indexing
    top = flat.take(y0 * width + x0, axis=0) * (1.0 - fx) + flat.take(y0 * width + x1, axis=0) * fx
    bottom = flat.take(y1 * width + x0, axis=0) * (1.0 - fx) + flat.take(y1 * width + x1, axis=0) * fx
    return top * (1.0 - fy) + bottom * fy


def _blur(image: np.ndarray, sigma: float) -> tuple[np.ndarray, int]:
    """``image`` (H, W, C) blurred by a Gaussian of ``sigma`` pixels, held at 1/f of its
    resolution (f the largest power of 2 up to sigma / 2): the mean of f x f blocks, then a
    Gaussian of the variance the blocks leave, (sigma^2 - (f^2 - 1) / 12) / f^2 in the coarse
    pixels. A coarse pixel's centre lies at f x its coordinates (:func:`_sample` at xy / f).
    A wide Gaussian at full resolution would cost sigma x more for the same smooth image.

    Returns
    -------
    (ceil(H / f), ceil(W / f), C) float32 image and f.
    """
    f = 1
    while 4 * f <= sigma:
        f *= 2
    image = image.astype(np.float32)
    if f > 1:   # zero-padded to whole blocks, as the blur's border is zero
        height, width = -(-image.shape[0] // f), -(-image.shape[1] // f)
        padded = np.zeros((height * f, width * f, image.shape[2]), dtype=np.float32)
        padded[:image.shape[0], :image.shape[1]] = image
        image = padded.reshape(height, f, width, f, -1).mean(axis=(1, 3))
    rest = np.sqrt(max(sigma ** 2 - (f ** 2 - 1) / 12.0, 0.0)) / f
    return gaussian_filter(image, sigma=(rest, rest, 0), mode="constant"), f


def _align(observed: np.ndarray, gradients: np.ndarray, factor: int, template: np.ndarray,
           points_world: np.ndarray, camera: Camera, steps: int, free: np.ndarray, fallback: Camera | None = None,
           min_move: float = POSE_MIN_MOVE) -> tuple[Camera, float, float]:
    """Damped Gauss-Newton alignment at one level of the parameters where ``free`` (6,) bool
    is set, from ``camera`` or from ``fallback`` when that fits this level better (so the
    result never fits worse than either); ``observed`` (H', W', C) is the level's image at
    1/``factor`` of the camera's resolution and ``gradients`` (H', W', 2C) its column then row
    derivatives per camera pixel (:class:`ObservedLevels`). It stops after ``steps`` steps, or
    when a step lowers the cost by less than :data:`POSE_MIN_GAIN` or moves no point by more
    than ``min_move`` pixels. Returns (camera, cost before, cost after)."""
    channels = observed.shape[2]
    scale = max(float(np.median(np.abs(template))), 1e-6)

    def residual(cam: Camera):
        xy, depth = cam.project(points_world)
        inside = (depth > 0) & (xy[:, 0] >= 0) & (xy[:, 0] <= cam.width) & (xy[:, 1] >= 0) & (xy[:, 1] <= cam.height)
        r = np.where(inside[:, None], _sample(observed, xy / factor) - template, 0.0) / scale
        return r, xy, inside

    pivot_world = points_world.mean(axis=0)   # the camera turns about the seen surface's centre
    cam, damping = camera, 1e-3
    r, xy, inside = residual(cam)
    spread = robust_scale(np.linalg.norm(r[inside], axis=1))   # fixed for the level: one cost throughout

    def cost(r):   # the Cauchy loss whose IRLS weights are used below
        return float(np.sum(np.log1p((np.linalg.norm(r, axis=1) / (TUNING["cauchy"] * spread)) ** 2)))

    if fallback is not None:
        r_f, xy_f, inside_f = residual(fallback)
        if cost(r_f) < cost(r):
            cam, r, xy, inside = fallback, r_f, xy_f, inside_f
    first = current = cost(r)
    for _ in range(steps):
        w2c = np.linalg.inv(cam.c2w)
        p_cam = points_world @ w2c[:3, :3].T + w2c[:3, 3]
        pivot = w2c[:3, :3] @ pivot_world + w2c[:3, 3]
        j_pix = projection_jacobian(p_cam, pivot, cam.fx, cam.fy)                      # (N, 2, 6)
        g = _sample(gradients, xy / factor).reshape(-1, 2, channels)            # (N, 2, C)
        jac = np.matmul(g.transpose(0, 2, 1), j_pix) / scale                    # (N, C, 6)
        w = irls_weights(np.linalg.norm(r, axis=1), "cauchy", spread) * inside
        jac = jac.reshape(-1, 6)[:, free]
        w, rr = np.repeat(w, channels), r.reshape(-1)
        normal = jac.T @ (jac * w[:, None])
        rhs = -jac.T @ (w * rr)
        while damping < 1e8:
            delta = np.zeros(6)
            delta[free] = np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-12), rhs)
            if not np.all(np.isfinite(delta)):
                damping *= 10.0
                continue
            trial = dataclasses.replace(cam, c2w=cam.c2w @ rigid_update(delta, pivot))
            r_t, xy_t, inside_t = residual(trial)
            c_t = cost(r_t)
            if c_t < current:
                gain = 1.0 - c_t / current
                moved = float(np.max(np.abs(xy_t - xy)[inside & inside_t], initial=0.0))
                cam, r, xy, inside, current = trial, r_t, xy_t, inside_t, c_t
                damping = max(damping / 3.0, 1e-6)
                break
            damping *= 10.0
        else:
            break
        if gain < POSE_MIN_GAIN or moved < min_move:
            break
    return cam, first, current


def _gradients(image: np.ndarray, factor: int) -> np.ndarray:
    """(H', W', 2C) column then row derivatives of a level's ``image`` (H', W', C) held at
    1/``factor`` of the camera's resolution, per camera pixel."""
    grad_row, grad_col = np.gradient(image, axis=(0, 1))
    return np.concatenate([grad_col, grad_row], axis=2) / factor


class ObservedLevels:
    """One view's observed image and alpha blurred at each level (:func:`_blur`), with their
    gradients, made on first use and kept: the images do not change between the rounds of a
    pose refinement, only the camera, and the blur and the gradients are linear, so the
    silhouette channel's weight (the colours' level, which the prediction sets) scales the
    kept alpha level instead of being blurred anew. Levels are kept up to ``max_bytes`` (None:
    all); those beyond it are made again on each use.

    Attributes
    ----------
    colour : (H, W, 3) the view's colours times its alpha (the object alone).
    alpha : (H, W) or None, the view's :func:`silhouette`.
    """

    def __init__(self, view: View, max_bytes: int | None = None):
        self.alpha = silhouette(view)
        self.colour = view.rgb if view.alpha is None else view.rgb * view.alpha[..., None]
        self._levels: dict[tuple[str, float], tuple[np.ndarray, np.ndarray, int]] = {}
        self._left = np.inf if max_bytes is None else max_bytes

    def _level(self, part: str, sigma: float) -> tuple[np.ndarray, np.ndarray, int]:
        key = (part, sigma)
        if key in self._levels:
            return self._levels[key]
        image = self.colour if part == "colour" else self.alpha[..., None]
        blurred, factor = _blur(image, sigma)
        level = blurred, _gradients(blurred, factor), factor
        size = blurred.nbytes + level[1].nbytes
        if size <= self._left:   # kept, and shared by every later use: read-only
            for array in level[:2]:
                array.setflags(write=False)
            self._levels[key], self._left = level, self._left - size
        return level

    def level(self, sigma: float, colour: bool, silhouette_weight: float) -> tuple[np.ndarray, np.ndarray, int]:
        """(image (H', W', C), gradients (H', W', 2C), factor) at the level ``sigma``: the
        colours (``colour``) then, with an alpha, the silhouette times ``silhouette_weight``."""
        parts = ([self._level("colour", sigma)] if colour else []) + (
            [] if self.alpha is None else [self._level("alpha", sigma)])
        weights = [1.0] * colour + [silhouette_weight] * (self.alpha is not None)
        if len(parts) == 1 and weights[0] == 1.0:
            return parts[0]
        image = np.concatenate([w * p[0] for w, p in zip(weights, parts)], axis=2)
        channels = [p[0].shape[2] for p in parts]
        gradients = np.concatenate([w * p[1][..., k * c:(k + 1) * c] for k in (0, 1)
                                    for w, p, c in zip(weights, parts, channels)], axis=2)
        return image, gradients, parts[0][2]


def _fill_unestimated(predicted: np.ndarray, known: np.ndarray, mesh: np.ndarray, sigma: float) -> np.ndarray:
    """``predicted`` (H, W, C) with its mesh pixels that have no estimate (``mesh`` (H, W, 1)
    bool and not ``known`` (H, W, 1) bool) set to the Gaussian-weighted mean (``sigma``
    pixels) of the known pixels around them (normalised convolution). Left black, they would
    darken their known neighbours once the image is blurred, where the observed image is not
    dark; ``sigma`` is the widest level's, as far as its blur carries them. Pixels with no known
    one within reach stay as they are."""
    unknown = mesh & ~known
    if not unknown.any():
        return predicted
    weights = known.astype(np.float32)
    spread = gaussian_filter(weights, (sigma, sigma, 0), mode="constant")
    reach = spread > 1e-3
    mean = gaussian_filter(predicted * weights, (sigma, sigma, 0), mode="constant") / np.where(reach, spread, 1.0)
    return np.where(unknown & reach, mean, predicted).astype(np.float32)


def _refine(view: View, caster: RayCaster, predicted: np.ndarray | None, scales: tuple[float, ...],
            steps: int, free: np.ndarray, estimated: np.ndarray | None = None,
            observed: ObservedLevels | None = None) -> tuple[Camera, dict]:
    """One view's camera aligned from coarse to fine: the ``predicted`` image (H, W, 3) of
    the view at its camera and the silhouette against the image and its alpha, or the
    silhouette alone (``predicted`` None). ``estimated`` (F,) bool: the faces whose predicted
    radiance is known; pixels on the others are not aligned (their prediction is black), and
    their prediction is filled from the known pixels around them before the blur
    (:func:`_fill_unestimated`). ``observed``: the view's kept levels (None: made here)."""
    cam = view.camera
    info = {"pixels": 0, "cost": [0.0, 0.0], "too_small": False}
    observed = observed or ObservedLevels(view)
    # the surface points and their predicted radiance, at the starting pose: a pose error of a
    # few pixels barely changes what a point looks like, only where it lands
    face, surface = caster.pixel_hits(cam)
    # the silhouette channel is the whole mesh's, taken before unestimated faces are dropped
    coverage = (face >= 0).reshape(cam.height, cam.width, 1).astype(np.float32)
    if estimated is not None:   # a face without an estimate has no predicted radiance to align with
        face = np.where(estimated[np.maximum(face, 0)], face, -1)
    if np.count_nonzero(face >= 0) < POSE_MIN_POINTS or (predicted is None and observed.alpha is None):
        info["too_small"] = bool(np.count_nonzero(face >= 0) < POSE_MIN_POINTS)
        return cam, info
    level, colour = 1.0, predicted is not None
    if not colour:
        predicted = coverage
    else:
        predicted = _fill_unestimated(predicted, (face >= 0).reshape(coverage.shape), coverage > 0, max(scales))
        if observed.alpha is not None:   # the silhouette as one more channel, at the colours' level
            level = float(np.median(np.linalg.norm(predicted.reshape(-1, 3)[face >= 0], axis=1)))
            predicted = np.concatenate([predicted, level * coverage], axis=2)
    rows, cols = np.divmod(np.arange(len(face)), cam.width)
    # a regular grid of pixels: a blurred level needs fewer samples, and none needs more than
    # POSE_MAX_POINTS
    thinned = int(np.ceil(np.sqrt(np.count_nonzero(face >= 0) / POSE_MAX_POINTS)))
    for k, sigma in enumerate(scales):
        stride = max(1, int(sigma // 2), thinned)
        covered = np.nonzero((face >= 0) & (rows % stride == 0) & (cols % stride == 0))[0]
        if len(covered) < POSE_LEVEL_POINTS:
            continue
        blurred, factor = _blur(predicted, sigma)
        template = _sample(blurred, (np.stack([cols[covered], rows[covered]], axis=1) + 0.5) / factor)
        finest = k == len(scales) - 1   # the result must fit at least as well as the given pose
        image, gradients, factor = observed.level(sigma, colour, level)
        cam, before, after = _align(image, gradients, factor, template, surface[covered], cam, steps, free,
                                    view.camera if finest else None, POSE_MIN_MOVE * sigma)
        info["pixels"], info["cost"] = int(len(covered)), [before, after]
    return cam, info


def silhouette(view: View) -> np.ndarray | None:
    """The view's alpha (H, W) clipped to [0, 1] when it has a background (some pixel below
    0.5); None otherwise: an alpha of ones (an opaque image) says nothing about the outline."""
    if view.alpha is None or not np.any(view.alpha < 0.5):
        return None
    return np.clip(view.alpha, 0.0, 1.0)


def refine_view(view: View, predictor: Predictor, scales: tuple[float, ...] = POSE_SCALES,
                steps: int = POSE_STEPS, observed: ObservedLevels | None = None) -> tuple[Camera, dict]:
    """One view's camera (all 6 degrees of freedom) aligned with ``predictor``'s image of it;
    ``observed``: the view's kept levels, where a caller aligns it again (None: made here).

    Returns
    -------
    camera : the refined Camera (the input one when too few pixels are covered).
    info : dict with 'pixels' used and 'cost' (robust cost before and after, finest level).
    """
    return _refine(view, predictor.caster, predictor.predict(view.camera)[0], scales, steps, np.ones(6, dtype=bool),
                   predictor.estimate.observed, observed)


def centre_view(view: View, caster: RayCaster, scales: tuple[float, ...] = SILHOUETTE_SCALES,
                steps: int = POSE_STEPS, observed: ObservedLevels | None = None) -> Camera:
    """One view's camera moved (no turn) so the mesh's silhouette matches the view's alpha:
    the pose error that shifts the whole object, found without any estimate. Views without
    alpha keep their camera. ``observed``: the view's kept levels (None: made here)."""
    free = np.array([False, False, False, True, True, True])
    return _refine(view, caster, None, scales, steps, free, observed=observed)[0]


def pose_change(before: Camera, after: Camera) -> dict:
    """{'rotation_deg', 'translation'} of the motion from ``before`` to ``after``."""
    correction = np.linalg.inv(before.c2w) @ after.c2w
    cos = np.clip(0.5 * (np.trace(correction[:3, :3]) - 1.0), -1.0, 1.0)
    return {"rotation_deg": float(np.degrees(np.arccos(cos))),
            "translation": float(np.linalg.norm(after.center - before.center))}


def approach(before: Camera, after: Camera, centre: np.ndarray) -> float:
    """The share of its distance to ``centre`` (3,) by which the camera moved closer from
    ``before`` to ``after`` (negative: farther). Every view of a capture moved alike is what a
    wrong scale does (a focal length, or a mesh in other units), not what pose noise does."""
    start = float(np.linalg.norm(before.center - centre))
    return (start - float(np.linalg.norm(after.center - centre))) / max(start, 1e-300)


def outline_offsets(data: MultiViewData, caster: RayCaster) -> np.ndarray:
    """(V,) how far, in pixels, each view's alpha outline lies from the mesh's outline under
    its camera: pixels where exactly one of (pixel centre sees the mesh, alpha >= 0.5) holds,
    over the mesh outline's length in pixels (a disc shifted by s pixels gives about 0.64 s).
    NaN for a view without a usable alpha (:func:`silhouette`). Correct poses give 0.01-0.3 px (edge pixels split by the
    0.5 threshold); 0.5 degrees of jitter gives several pixels."""
    buffers = caster.face_id_buffers([v.camera for v in data.views])
    out = np.full(len(data.views), np.nan)
    for k, (view, buffer) in enumerate(zip(data.views, buffers)):
        alpha = silhouette(view)
        if alpha is None:
            continue
        covered = buffer >= 0
        padded = np.pad(covered, 1, mode="edge")   # the image border is not an outline
        inner = (covered & padded[:-2, 1:-1] & padded[2:, 1:-1] & padded[1:-1, :-2] & padded[1:-1, 2:])
        outline = np.count_nonzero(covered & ~inner)
        out[k] = np.count_nonzero(covered ^ (alpha >= 0.5)) / max(outline, 1)
    return out


def reprojection_error(cameras: list[Camera], truth: list[Camera], points: np.ndarray) -> np.ndarray:
    """(V,) RMS distance in pixels between where each camera and its true pose project
    ``points`` (N, 3): how far a refined pose is from the truth, in the unit that matters
    (a turn about the object and a shift can nearly cancel, so degrees alone say little)."""
    return np.array([np.sqrt(np.mean(np.sum((a.project(points)[0] - b.project(points)[0]) ** 2, axis=1)))
                     for a, b in zip(cameras, truth)])


def plausible(before: Camera, after: Camera, centre: np.ndarray) -> bool:
    """Whether ``after`` lies within :data:`POSE_MAX_DEGREES` and :data:`POSE_MAX_SHIFT` x the
    distance to ``centre`` (3,) of ``before``."""
    change = pose_change(before, after)
    return (change["rotation_deg"] <= POSE_MAX_DEGREES
            and change["translation"] <= POSE_MAX_SHIFT * np.linalg.norm(before.center - centre))


def _settled(start: list, views: list, probe: np.ndarray) -> bool:
    """Whether a round moved no view (from ``start`` to ``views``) by :data:`POSE_MIN_MOVE`
    pixels at the points ``probe`` (N, 3): what the finest level resolves, so a further round
    would repeat this one."""
    shift = reprojection_error([v.camera for v in start], [v.camera for v in views], probe)
    return float(np.max(shift, initial=0.0)) < POSE_MIN_MOVE


def _log_round(log, data: MultiViewData, views: list, reverted: np.ndarray, r: int, rounds: int,
               settled: bool) -> None:
    """Round ``r``'s line (and, when it ``settled`` with rounds left, that they are skipped)."""
    if not log:
        return
    moved = [pose_change(a.camera, b.camera)["rotation_deg"] for a, b in zip(data.views, views)]
    log(f"pose refinement round {r + 1}/{rounds}: median correction {np.median(moved):.3f} deg; "
        f"{int(reverted.sum())} view(s) back at their pose before the round (the alignment moved their "
        f"outline beyond {POSE_OUTLINE_TOLERANCE:g} px, and farther than it was)")
    if settled and r + 1 < rounds:
        log(f"pose refinement: round {r + 1} moved no view by {POSE_MIN_MOVE:g} px; the remaining "
            f"{rounds - r - 1} round(s) are skipped")


def refine_poses(data: MultiViewData, solve: Callable[[MultiViewData, Estimate | None], Estimate],
                 rounds: int = POSE_ROUNDS,
                 folds: int = PoseConfig.pose_folds, caster: RayCaster | None = None, log=None
                 ) -> tuple[MultiViewData, list[dict]]:
    """Every training view's camera refined, the mesh and images kept.

    First each camera is moved so the silhouette matches the view's alpha. Then, ``rounds``
    times, the views are split into ``folds`` interleaved groups; each group in turn is
    aligned with the image predicted by ``solve`` on the other groups (at their poses so far),
    so a view is never pulled toward an estimate that already holds its own misregistered
    pixels. On a specular surface that includes the light: each highlight is seen by a few
    views only, so a view's shifted highlight pulls the fitted light's lobe (an estimate from
    all views, its faces' albedos refitted per group, left a 1 deg jitter without alpha at
    1.7 px where held-out estimates reach 0.9 px).

    Parameters
    ----------
    solve : (MultiViewData, prior) -> Estimate: the method that will run on the refined data;
        ``prior`` is the held-out estimate of the same view group in the previous round, or
        the previous group's in the first (None for the first), where the solve may start.
    caster : ray queries of ``data.mesh`` (None: built with the default variant).
    rounds : alignment rounds (at least 1).
    folds : view groups per round (2 to the number of views). When an estimate from the
        other groups would hold fewer than :data:`POSE_MIN_VIEWS` views, only the
        silhouette step runs.

    A view whose correction grows beyond :func:`plausible` goes back to its silhouette-only
    pose, or to its given pose when that too is beyond it (and is marked 'diverged'): it was
    pulled by a poor estimate, not by its pixels. A round that moves no view by
    :data:`POSE_MIN_MOVE` pixels (the reprojection of the mesh's vertices; what the finest level
    resolves) ends the refinement: the rounds after it would repeat it. After each round, a view whose alpha
    outline the round left more than :data:`POSE_OUTLINE_TOLERANCE` pixels from the mesh's,
    and farther than before the round (:func:`outline_offsets`), returns to its pose before
    the round: the alpha does not depend on the estimate, so it vetoes an alignment that a
    poor prediction of the view pulled off. Its 'pixels' and 'cost' then
    describe the alignment that was thrown away. Where the views outside a group determine no estimate
    (``solve`` raises :class:`InputError`: a singular solve from too few views), that group's
    views keep their poses for the round ('unaligned_rounds' counts such rounds).

    Returns
    -------
    data : the data with the refined cameras.
    info : one dict per view: 'name', 'rotation_deg' and 'translation' (world units) of the
        correction, 'approach' (:func:`approach`: the share of its distance the camera moved
        closer to the object), 'c2w' (4x4 list), 'diverged' (bool), 'unaligned_rounds' (int),
        'outline_reverted' (bool: the last round's alignment was undone by the outline
        check, the view keeping its pose from before that round), 'outline_px' (the final
        pose's outline offset, None without alpha), 'pixels' and 'cost' of the last alignment,
        and 'too_small' (bool: too few of its pixels show estimated faces to align it,
        :data:`POSE_MIN_POINTS`).
    """
    n = len(data.views)
    if n < 2:
        raise InputError(f"pose refinement needs at least 2 training views (each is aligned against an estimate "
                         f"from the others), got {n}")
    if rounds < 1:
        raise InputError(f"pose refinement needs at least 1 round, got {rounds}")
    if not 2 <= folds <= n:
        raise InputError(f"pose refinement splits the views into 2 to {n} groups (one view group is aligned "
                         f"against an estimate from the others); got {folds}")
    caster = caster or RayCaster(data.mesh)
    centre = data.mesh.bounds_centre
    # the images' levels, kept across the rounds
    observed = [ObservedLevels(v, POSE_KEPT_BYTES // n) for v in data.views]
    centred = []
    for v, levels in zip(data.views, observed):
        cam = centre_view(v, caster, observed=levels)
        centred.append(dataclasses.replace(v, camera=cam if plausible(v.camera, cam, centre) else v.camera))
    views, diverged = list(centred), [False] * n
    offsets = outline_offsets(dataclasses.replace(data, views=centred), caster)   # NaN without alpha
    reverted = np.zeros(n, dtype=bool)
    last = [{"pixels": 0, "cost": [0.0, 0.0], "too_small": False}] * n   # the silhouette step alone: none aligned
    if n - -(-n // folds) < POSE_MIN_VIEWS:
        rounds = 0
        if log:
            log(f"pose refinement: {n} views in {folds} groups leave under {POSE_MIN_VIEWS} views per held-out "
                "estimate; only the silhouette step ran")
    estimates: list[Estimate | None] = [None] * folds
    unaligned = [0] * n
    probe = data.mesh.vertices[:: max(1, len(data.mesh.vertices) // 1000)]   # where a round's motion is measured
    for r in range(rounds):
        start, start_offsets = list(views), offsets   # where the outline check returns a view to
        for k in range(folds):
            held = [i for i in range(n) if i % folds == k]
            try:
                others = dataclasses.replace(data, views=[v for i, v in enumerate(views) if i % folds != k])
                estimate = solve(others, estimates[k] if r > 0 else estimates[k - 1])
            except InputError as exc:   # the other views do not determine an estimate: this group waits
                for i in held:
                    unaligned[i] += 1
                if log:
                    log(f"pose refinement round {r + 1}: no estimate from the views outside group {k + 1} ({exc}); "
                        f"its {len(held)} views keep their poses this round")
                continue
            estimates[k] = estimate
            predictor = Predictor(data.mesh, estimate, caster)
            for i in held:
                cam, last[i] = refine_view(views[i], predictor, observed=observed[i])
                diverged[i] = not plausible(data.views[i].camera, cam, centre)
                views[i] = centred[i] if diverged[i] else dataclasses.replace(views[i], camera=cam)
        offsets = outline_offsets(dataclasses.replace(data, views=views), caster)
        # NaN (no alpha) compares False: such a view keeps its alignment; a diverged one is
        # already back at its silhouette pose
        reverted = (offsets > np.maximum(POSE_OUTLINE_TOLERANCE, start_offsets)) & ~np.array(diverged)
        for i in np.nonzero(reverted)[0]:
            views[i], offsets[i] = start[i], start_offsets[i]
        settled = _settled(start, views, probe)
        _log_round(log, data, views, reverted, r, rounds, settled)
        if settled:
            break
    info = [{"name": v.name, **pose_change(v.camera, w.camera), "approach": approach(v.camera, w.camera, centre),
             "c2w": w.camera.c2w.tolist(), "diverged": bad,
             "unaligned_rounds": skipped, "outline_reverted": bool(undone),
             "outline_px": None if np.isnan(offset) else float(offset), **extra}
            for v, w, bad, skipped, undone, offset, extra
            in zip(data.views, views, diverged, unaligned, reverted, offsets, last)]
    return dataclasses.replace(data, views=views), info
