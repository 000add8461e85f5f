"""The light as a dielectric coat reflects it: a lat-long map fitted to how colours change with the view.

A coated (plastic) face seen from view v shows, per colour channel,

    rgb_fv = D_f (1 - F(n . v)) + F(n . v) L(r_fv)

with D_f its diffuse radiance (unknown, one per face: the texture), F the Fresnel
reflectance of the coat (index ``ior``), r the mirror direction of v about the normal and
L the distant light. Mitsuba's ``plastic`` transmits the diffuse radiance through the
coat with 1 - F(n . v) (``roughplastic`` nearly so), so both terms change with the view.
Both are linear: the per-face D_f are eliminated (each face's rows projected off its
transmission column, formed as the Schur complement of the faces' diagonal block), and L,
a map of ``height`` x ``width`` vertices sampled bilinearly (:mod:`estimator.core.latlong`),
solves a weighted least-squares problem with a smoothness
penalty on neighbouring vertices, reweighted by a robust loss (glints of a sun narrower
than a cell, pixels mixing a face's texture differently from view to view). Rows whose
mirror direction the object itself blocks (the shadow function) show the object, not the
light, and are left out.

The diffuse albedo does not enter: a texture, however its colours vary, cannot bias this
light, which is where the albedo-edge fit (:mod:`estimator.light.edge_fit`) is weakest. The
light's DC relative to D_f is fixed only by F's change with the view angle (0.04-0.09 over
the views within 60 degrees of the normal), and a sun narrower than a cell reaches the map
blurred: ``retinex-segmented`` uses the whole map as a texture's light, or its sky beside a
sun with exact shadows (:meth:`ReflectedLight.sky_and_sun`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg, sparse

from ..core import latlong, sh
from ..core.errors import InputError
from ..core.settings import Section
from ..model.reflection import fresnel_dielectric, mirror_directions, mirror_shadow
from ..rays.visibility import SphereSampling, Visibility
from ..solvers import robust
from .coat import CoatConfig

ROWS_PER_VERTEX = 4  # rows beyond the per-face unknowns per map vertex for a determined map
# the reweighted rounds' conjugate gradients: relative residual and iteration cap
CG_TOLERANCE = 1e-8
CG_ITERATIONS = 200
# after CG_PROBE iterations a channel whose residual, shrinking at the rate seen so far, would
# reach the goal only after more than CG_DENSE_ITERATIONS is handed to its dense system. Only
# the time depends on it (either way the map is solved to CG_TOLERANCE): at the default 32 x 64
# map one channel's dense system, formed and factored, took 120-150 ms on the 2-core development
# machine, as long as 40-65 iterations on the real-light family's coated members, and the rate
# after 8 iterations foretold the count a solve took within about 30 % (mostly under it)
CG_PROBE = 8
CG_DENSE_ITERATIONS = 48


@dataclass
class CoatMapConfig(Section):
    """The light from the coat's reflection (:func:`fit_reflected_light`).

    Attributes
    ----------
    reflected_light : try the coat's reflected light (a lat-long map fitted to the colours'
        changes across views, every face's diffuse free, so no albedo can bias it).
    reflected_regions : try it on objects of uniform regions too (each region then takes its
        faces' median albedo under that light).
    reflected_sun_max_ratio : the map's brightest compact source becomes a sun with exact
        shadows when it lowers the edges' robust cost to at most this share.
    reflected_sun_max_angle : where the edge search kept a sun, the map's light replaces it
        only when the map's own sun lies within this many degrees of it (about a map cell).
    """

    reflected_light: bool = True
    reflected_regions: bool = True
    reflected_sun_max_ratio: float = 0.97
    reflected_sun_max_angle: float = 6.0

    def check(self):
        return [
            (self.reflected_sun_max_ratio >= 0, "reflected_sun_max_ratio must be >= 0"),
            (0 <= self.reflected_sun_max_angle <= 180, "reflected_sun_max_angle must lie in [0, 180] degrees"),
        ]


@dataclass(frozen=True)
class ReflectedLight:
    """Result of :func:`fit_reflected_light`.

    Attributes
    ----------
    radiance : (H, W, 3) lat-long light map (Mitsuba's ``envmap`` orientation).
    diffuse : (F, 3) each face's diffuse radiance with the coat's reflection removed (NaN
        where a face has no usable row).
    explained : (3,) share of the view-dependent variance (over the rows, after removing each
        face's diffuse) that the reflected light explains, per channel, robust-weighted.
    rows : number of rows used.
    determined : at least :data:`ROWS_PER_VERTEX` rows per vertex beyond the faces' own
        unknowns. A map with fewer rows than that fits the noise: it explains nearly all of
        the view changes whatever the light (30 views of 256² on a 5,120-face object give about
        10 rows per vertex; 12 views of 80², under one). Such a map is not fitted, nor one
        whose first system is not positive definite in floating point: its radiance is 0, its
        diffuse NaN and its ``explained`` 0.
    """

    radiance: np.ndarray
    diffuse: np.ndarray
    explained: np.ndarray
    rows: int
    determined: bool

    def sh(self, order: int) -> np.ndarray:
        """((order + 1)^2, 3) SH projection of the map."""
        return sh.project_latlong(order, self.radiance)

    def sky_and_sun(self, radius: float = 12.0, ring: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
        """The map without its brightest compact source, and that source's direction.

        The brightest vertex (mean over channels) and its neighbours within ``radius``
        degrees are replaced by the median of the ring out to ``ring`` degrees (a sun's
        reflection, blurred over a few cells); the direction is the centroid of the excess
        over that median within ``radius``.

        Returns
        -------
        sky : (H, W, 3) map.
        direction : (3,) unit direction of the source.
        """
        h, w = self.radiance.shape[:2]
        dirs = latlong.directions(h, w).reshape(-1, 3)
        values = self.radiance.reshape(-1, 3)
        peak = dirs[np.argmax(values.mean(axis=1))]
        angle = np.degrees(np.arccos(np.clip(dirs @ peak, -1.0, 1.0)))
        inner, annulus = angle <= radius, (angle > radius) & (angle <= ring)
        level = np.median(values[annulus], axis=0) if annulus.any() else np.zeros(3)
        excess = np.maximum(values[inner] - level, 0.0).mean(axis=1) * latlong.solid_angles(h, w).reshape(-1)[inner]
        centroid = excess @ dirs[inner] if excess.sum() > 0 else peak
        sky = values.copy()
        sky[inner] = level
        return sky.reshape(h, w, 3), centroid / np.linalg.norm(centroid)


def bilinear_rows(dirs: np.ndarray, height: int, width: int) -> sparse.csr_matrix:
    """(N, H*W) sparse weights that sample a lat-long map of vertices bilinearly at the unit
    directions (N, 3), as :func:`estimator.core.latlong.sample_bilinear` does."""
    uv = latlong.to_uv(dirs)
    x = uv[:, 0] * width
    y = uv[:, 1] * (height - 1)
    x0 = np.floor(x).astype(np.int64)
    y0 = np.clip(np.floor(y).astype(np.int64), 0, height - 2)
    fx, fy = x - x0, np.clip(y - y0, 0.0, 1.0)
    x0 %= width
    x1 = (x0 + 1) % width
    n = len(dirs)
    cols = np.stack([y0 * width + x0, y0 * width + x1, (y0 + 1) * width + x0, (y0 + 1) * width + x1], 1)
    vals = np.stack([(1 - fy) * (1 - fx), (1 - fy) * fx, fy * (1 - fx), fy * fx], 1)
    return sparse.csr_matrix((vals.ravel(), (np.repeat(np.arange(n), 4), cols.ravel())), shape=(n, height * width))


def map_differences(height: int, width: int) -> sparse.csr_matrix:
    """(P, H*W) differences of neighbouring vertices of a lat-long map: along each row (wrapping
    in azimuth, weighted by sin(theta): those neighbours are closer) and down each column."""
    idx = np.arange(height * width).reshape(height, width)
    pairs = np.concatenate([np.stack([idx.ravel(), np.roll(idx, -1, axis=1).ravel()], 1),
                            np.stack([idx[:-1].ravel(), idx[1:].ravel()], 1)])
    theta = np.pi * np.arange(height) / (height - 1)
    weight = np.concatenate([np.repeat(np.maximum(np.sin(theta), 0.5 / height), width),
                             np.ones((height - 1) * width)])
    rows = np.tile(np.arange(len(pairs)), 2)
    return sparse.csr_matrix((np.concatenate([weight, -weight]), (rows, pairs.T.ravel())),
                             shape=(len(pairs), height * width))


def fit_reflected_light(face: np.ndarray, rgb: np.ndarray, view_dir: np.ndarray, normals: np.ndarray,
                        sampling: SphereSampling, visibility: Visibility, ior: float = CoatConfig.coat_ior,
                        height: int = 32, width: int = 64, smoothness: float = 1e-3, rounds: int = 4,
                        loss: str = "cauchy") -> ReflectedLight:
    """Fit the light a dielectric coat reflects, with every face's diffuse radiance free.

    Parameters
    ----------
    face : (N,) face of each observation.
    rgb : (N, 3) observed colour (linear).
    view_dir : (N, 3) unit direction from the face to the camera.
    normals : (F, 3) unit face normals.
    sampling, visibility : the shadow function (rows whose mirror direction is blocked are
        left out).
    ior : the coat's index of refraction.
    height, width : the map's vertices (>= 3 x 2).
    smoothness : weight of the squared differences of neighbouring vertices, relative to the
        data term's mean diagonal.
    rounds : reweighting rounds of the robust ``loss``.

    Returns
    -------
    :class:`ReflectedLight`.
    """
    face = np.asarray(face, dtype=np.int64)
    n_faces = len(normals)
    if rgb.shape != (len(face), 3) or view_dir.shape != (len(face), 3):
        raise InputError(f"rgb and view_dir must be (N, 3) with N = {len(face)} observations, "
                         f"got {rgb.shape} and {view_dir.shape}")
    if len(face) and (face.min() < 0 or face.max() >= n_faces):
        raise InputError(f"observation faces must lie in [0, {n_faces})")
    if ior <= 1.0:
        raise InputError(f"the coat's ior must exceed 1, got {ior}")
    if height < 3 or width < 2:
        raise InputError(f"the light map needs at least 3 x 2 vertices, got {height} x {width}")
    keep, mirror, fresnel = _reflecting_rows(face, view_dir, normals, sampling, visibility, ior)
    face, rgb = face[keep], rgb[keep]
    rows = len(face)
    if rows == 0:
        raise InputError("no observation sees the light reflected by the coat (every mirror direction is blocked)")
    cells = height * width
    spare = rows - len(np.unique(face))
    undetermined = ReflectedLight(np.zeros((height, width, 3)), np.full((n_faces, 3), np.nan), np.zeros(3), rows,
                                  False)
    if spare < ROWS_PER_VERTEX * cells:   # too few rows to determine the map: not fitted (it would fit the noise)
        return undetermined
    transmit = 1.0 - fresnel
    a = (sparse.diags(fresnel) @ bilinear_rows(mirror, height, width)).tocsr()   # (N, H*W)
    b = sparse.csr_matrix((transmit, (np.arange(rows), face)), shape=(rows, n_faces))
    smooth = map_differences(height, width)
    ridge = smoothness * (smooth.T @ smooth) + 1e-9 * sparse.identity(cells)   # (cells, cells), per unit level
    # the first round weighs every row alike: one dense system for the three channels, factored
    system, right, faces_fit = _face_eliminated_system(a, b, rgb, np.ones(rows))
    try:
        first = _factored(system, ridge)
    except np.linalg.LinAlgError:   # not positive definite in floating point: the rows do not determine it
        return undetermined
    light = linalg.cho_solve(first, right, check_finite=False)
    residuals, projections = faces_fit(light), faces_fit(np.zeros_like(light))
    diffuse = np.full((n_faces, 3), np.nan)
    explained = np.zeros(3)

    def reweighted(residuals):
        return np.stack([robust.irls_weights(np.abs(r), loss, robust.robust_scale(np.abs(r), floor=1e-12))
                         for r in residuals.T], axis=1)

    weights = reweighted(residuals)
    for _ in range(max(rounds, 1) - 1):
        light, residuals, projections = _reweighted_solve(a, b, rgb, weights, ridge, first, light)
        weights = reweighted(residuals)
    for c in range(3):
        residual, projected, weight = residuals[:, c], projections[:, c], weights[:, c]
        total = np.sum(weight * projected ** 2)
        explained[c] = 1.0 - np.sum(weight * residual ** 2) / total if total > 0 else 0.0
        denominator = np.bincount(face, weight * transmit ** 2, minlength=n_faces)
        seen = denominator > 0
        diffuse[seen, c] = (b.T @ (weight * (rgb[:, c] - a @ light[:, c])))[seen] / denominator[seen]
    return ReflectedLight(light.reshape(height, width, 3), diffuse, explained, rows, True)


def diffuse_radiance(fitted: ReflectedLight, face: np.ndarray, rgb: np.ndarray, view_dir: np.ndarray,
                     normals: np.ndarray, sampling: SphereSampling, visibility: Visibility,
                     ior: float = CoatConfig.coat_ior, rounds: int = 4, loss: str = "cauchy") -> np.ndarray:
    """(F, 3) each face's diffuse radiance under the map of ``fitted``, held fixed: the
    per-face weighted least squares of :func:`fit_reflected_light` (the map's reflection
    removed, the coat's exit transmission divided out), reweighted ``rounds`` times by the
    robust ``loss`` of the residuals; NaN where a face has no usable row. Observations
    (``face``, ``rgb``, ``view_dir``: (N,), (N, 3), (N, 3)) of faces the map was not fitted on
    are welcome: this is how a map fitted on part of a mesh reaches the rest."""
    face = np.asarray(face, dtype=np.int64)
    keep, mirror, fresnel = _reflecting_rows(face, view_dir, normals, sampling, visibility, ior)
    face, rgb = face[keep], rgb[keep]
    height, width = fitted.radiance.shape[:2]
    transmit = 1.0 - fresnel
    values = rgb - fresnel[:, None] * (bilinear_rows(mirror, height, width) @ fitted.radiance.reshape(-1, 3))
    count = len(normals)
    diffuse = np.full((count, 3), np.nan)
    for c in range(3):
        weights = np.ones(len(face))
        for round_ in range(max(rounds, 1) + 1):
            denominator = np.bincount(face, weights * transmit ** 2, minlength=count)
            level = np.bincount(face, weights * transmit * values[:, c], minlength=count) / np.maximum(
                denominator, 1e-300)
            if round_ == max(rounds, 1):
                break
            residual = np.abs(values[:, c] - transmit * level[face])
            weights = robust.irls_weights(residual, loss, robust.robust_scale(residual, floor=1e-12))
        diffuse[denominator > 0, c] = level[denominator > 0]
    return diffuse


def _reflecting_rows(face, view_dir, normals, sampling, visibility, ior):
    """The rows that see the light the coat reflects: (N,) bool, facing the camera with an
    unblocked mirror direction; for those rows (n, 3) the mirror directions and (n,) the
    coat's Fresnel reflectance."""
    n = normals[face]
    cos = np.sum(n * view_dir, axis=1)
    mirror = mirror_directions(n, view_dir)
    keep = (cos > 0) & mirror_shadow(face, mirror, sampling, visibility)
    return keep, mirror[keep], fresnel_dielectric(cos[keep], ior)


def _reweighted_solve(a, b, values, weights, ridge, first, start):
    """A reweighted round of the map's fit, each channel under its own row weights: the maps
    (K, C) for ``values`` (N, C) at row ``weights`` (N, C), the rows' residuals (N, C) with each
    face's diffuse refitted under them and the values with each face's diffuse projected off.

    Each channel's system is that of :func:`_face_eliminated_system` plus its mean diagonal
    times ``ridge`` (K, K) sparse, never formed: conjugate gradients multiply by its sparse
    factors, preconditioned by ``first``, the Cholesky factor of the first round's system (every
    row weighed alike), and started from ``start`` (K, C), the previous round's maps. Robust
    weights lie in [0, 1] and change few rows much, so the first system is close to each
    reweighted one and a few iterations replace a dense factorisation per channel (K = 2048:
    75 ms each); the channels' iterations run side by side, so that each pass over the factor
    serves all of them. A channel the iterations leave short of :data:`CG_TOLERANCE` is solved
    by its dense system, formed and factored (by least squares where, its rows' weights nearly
    nil, the factorisation fails in floating point)."""
    channels = values.shape[1]
    k = a.shape[1]
    times, right, fits = [], np.zeros((k, channels)), []
    b_squared_t = b.multiply(b).T.tocsr()                                                   # (F, N)
    a_norms = np.asarray(a.multiply(a).sum(axis=1)).ravel()                                 # (N,) |a_n|^2
    for c in range(channels):
        weighted_a = sparse.diags(weights[:, c]) @ a
        denominator = b_squared_t @ weights[:, c]                                           # (F,) D
        inverse = np.where(denominator > 0, 1.0 / np.maximum(denominator, 1e-300), 0.0)
        p = (b.T @ weighted_a).tocsr()                                                      # (F, K) P
        p_t, a_t = p.T.tocsr(), weighted_a.T.tocsr()
        # the trace of a^T W a - P^T D^-1 P, as the dense system's mean diagonal sets the ridge
        trace = float(np.sum(weights[:, c] * a_norms) - np.sum(inverse * np.asarray(p.multiply(p).sum(axis=1)).ravel()))
        scaled = max(trace / k, 1e-300) * ridge
        times.append(lambda x, a_t=a_t, p=p, p_t=p_t, inverse=inverse, scaled=scaled:
                     a_t @ (a @ x) - p_t @ (inverse * (p @ x)) + scaled @ x)
        right[:, c] = a_t @ values[:, c] - p_t @ (inverse * (b.T @ (weights[:, c] * values[:, c])))
        fits.append(lambda light, c=c, inverse=inverse: _faces_refitted(a, b, values[:, c], weights[:, c], inverse,
                                                                          light))
    fitted, converged = _conjugate_gradients(times, lambda r: linalg.cho_solve(first, r, check_finite=False),
                                             right, start)
    for c in np.nonzero(~converged)[0]:
        system, right_c, _ = _face_eliminated_system(a, b, values[:, c], weights[:, c])
        try:
            fitted[:, c] = linalg.cho_solve(_factored(system, ridge), right_c, check_finite=False)
        except np.linalg.LinAlgError:   # rows the weights nearly remove leave it singular in floating point
            system, right_c, _ = _face_eliminated_system(a, b, values[:, c], weights[:, c])   # the factor overwrote it
            fitted[:, c] = linalg.lstsq(_with_ridge(system, ridge), right_c, check_finite=False)[0]
    residuals = np.stack([fit(fitted[:, c]) for c, fit in enumerate(fits)], axis=1)
    projections = np.stack([fit(np.zeros(k)) for fit in fits], axis=1)
    return fitted, residuals, projections


def _with_ridge(system: np.ndarray, ridge: sparse.spmatrix) -> np.ndarray:
    """The dense map system (K, K) plus its mean diagonal times ``ridge`` (K, K) sparse, in place."""
    system += max(np.trace(system) / system.shape[0], 1e-300) * ridge.toarray()
    return system


def _factored(system: np.ndarray, ridge: sparse.spmatrix):
    """The Cholesky factor of :func:`_with_ridge` of the dense map system (overwrites ``system``):
    symmetric positive definite, the ridge keeps it so (Cholesky takes two thirds of LU's time)."""
    return linalg.cho_factor(_with_ridge(system, ridge), overwrite_a=True, check_finite=False)


def _faces_refitted(a, b, values, weights, inverse, light):
    """(N,) the residuals of ``values`` (N,) under the map ``light`` (K,) with each face's
    diffuse refitted at row ``weights`` (N,) (``inverse`` (F,): 1 / its weighted transmission)."""
    rest = values - a @ light
    return rest - b @ (inverse * (b.T @ (weights * rest)))


def _conjugate_gradients(times, precondition, right, start) -> tuple[np.ndarray, np.ndarray]:
    """(K, C) solutions of C symmetric positive definite systems side by side: column c of
    ``right`` (K, C) by ``times[c]`` (a function of (K,)), each started at column c of ``start``,
    with one ``precondition`` (a function of (K, C)) applied to all columns at once, until each
    residual is :data:`CG_TOLERANCE` of the larger of its right side and its first residual
    (at most :data:`CG_ITERATIONS`); and (C,) bool, which columns got there. A column whose
    residual, after :data:`CG_PROBE` iterations, shrinks so slowly that at that geometric rate
    it would need more than :data:`CG_DENSE_ITERATIONS` in all is left there, not converged
    (the caller's dense solve is then the cheaper). Written here because scipy's ``cg`` takes
    one system and one right side."""
    x = start.copy()
    columns = range(right.shape[1])
    residual = right - np.stack([times[c](x[:, c]) for c in columns], axis=1)
    first = np.linalg.norm(residual, axis=0)
    goal = CG_TOLERANCE * np.maximum(np.linalg.norm(right, axis=0), first)
    z = precondition(residual)
    direction = z.copy()
    rz = np.sum(residual * z, axis=0)
    slow = np.zeros(len(goal), dtype=bool)
    for iteration in range(CG_ITERATIONS):
        norm = np.linalg.norm(residual, axis=0)
        if iteration == CG_PROBE:   # the iterations a column needs at the rate seen so far
            with np.errstate(divide="ignore", invalid="ignore"):
                needed = np.where(norm < first, CG_PROBE * np.log(goal / first) / np.log(norm / first), np.inf)
            slow = (norm > goal) & ~(needed <= CG_DENSE_ITERATIONS)
        active = (norm > goal) & ~slow
        if not active.any():
            break
        product = np.stack([times[c](direction[:, c]) if active[c] else np.zeros(len(x)) for c in columns], axis=1)
        curvature = np.sum(direction * product, axis=0)
        step = np.where(active, rz / np.where(active, curvature, 1.0), 0.0)
        x += step * direction
        residual -= step * product
        z = precondition(residual)
        rz_next = np.sum(residual * z, axis=0)
        direction = z + np.where(active, rz_next / np.where(rz > 0, rz, 1.0), 0.0) * direction
        rz = rz_next
    return x, np.linalg.norm(residual, axis=0) <= goal


def _face_eliminated_system(a, b, y, weights):
    """The map's weighted normal equations with every face's diffuse eliminated.

    ``a`` (N, K) are the rows of the map's vertices, ``b`` (N, F) each row's transmission in
    its face's column (one nonzero per row), ``y`` (N,) the values and ``weights`` (N,). With
    D = b^T W b diagonal (the faces' columns are disjoint; D^-1 taken as 0 for a face without
    weight) and P = b^T W a, the Schur
    complement a^T W a - P^T D^-1 P and a^T W y - P^T D^-1 b^T W y are the normal equations of
    the rows with each face's column projected off, formed without that projection's fill-in
    (a projected row holds every vertex its face's rows touch).

    Returns the (K, K) dense system, the (K,) right side and a function of the map (K,) that
    gives the (N,) residuals with each face's diffuse refitted under it (at the map 0: the
    values projected off the faces' columns). ``y`` (N, C) gives C right sides (K, C), the
    maps (K, C) and residuals (N, C) of C channels under the same weights.
    """
    weighted_a = sparse.diags(weights) @ a
    denominator = np.asarray((b.multiply(b).T @ weights)).ravel()                   # (F,) D
    inverse = np.where(denominator > 0, 1.0 / np.maximum(denominator, 1e-300), 0.0)
    p = (b.T @ weighted_a).tocsr()                                                  # (F, K) P
    system = (a.T @ weighted_a).toarray() - (p.T @ sparse.diags(inverse) @ p).toarray()
    w, inverse_y = (weights, inverse) if y.ndim == 1 else (weights[:, None], inverse[:, None])
    right = a.T @ (w * y) - p.T @ (inverse_y * (b.T @ (w * y)))

    def faces_fit(light: np.ndarray) -> np.ndarray:
        rest = y - a @ light
        return rest - b @ (inverse_y * (b.T @ (w * rest)))

    return system, right, faces_fit
