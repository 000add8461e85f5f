"""How far an estimate can be trusted, from its inputs alone (no ground truth).

The estimate re-predicts every observation it was solved from; the residuals, relative to
each face's median colour, give per-view residuals and outlier shares, a per-face standard
error of the diffuse albedo, and the condition of the light's normal equations. Each
diagnostic that makes the result doubtful becomes one warning line.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..core import sh
from ..light.sun import sun_shadings
from ..model.estimate import Estimate
from ..pipeline.exposure import view_gains
from ..pipeline.prepared import ROW_CHUNK, Prepared
from ..solvers.robust import exposure_level, relative_residuals, robust_scale

OUTLIER_SIGMAS = 3.0        # a row is an outlier beyond this many robust scales
MIN_OUTLIER_SCALE = 0.01    # ... the scale taken as at least 1 % of the exposure level (noise-free data)
GROSS_RESIDUAL = 0.2        # a gross error: residual above 20 % of the exposure level
OUTLIER_VIEW_SHARE = 0.05   # a view is an outlier when this share of its rows are gross errors ...
OUTLIER_VIEW_FACTOR = 5.0   # ... and this many times the median view's share ...
OUTLIER_VIEW_ROWS = 10      # ... and at least this many rows (a few faces of a small view are chance) ...
NEIGHBOUR_VIEWS = 3         # ... and OUTLIER_VIEW_FACTOR x the median gross share of its this many nearest views
HIGH_RESIDUAL = 0.15        # median relative residual above which the model fits poorly
ILL_CONDITIONED = 1e7       # condition number of the light's normal equations
MAX_UNKEPT = 0.2            # share of faces without a kept observation
IMPRECISE_ALBEDO = 0.10     # the median face's relative albedo standard error beyond the ±10 % the reports score
# a view's exposure (its gain against the others, view_gains) is off when it differs from its
# NEIGHBOUR_VIEWS nearest views' median by more than the ±10 % band the reports score and by more
# than this many robust scales of that difference over the views: a reflection moves the gains
# of neighbouring views together, and on the random family's 40 development and validation seeds
# (1000-1019, 1040-1059) no view's gain stood more than 5.5 scales from its neighbours'
EXPOSURE_SIGMAS = 6.0
PLANE_MARGIN = 1e-3         # cosine above a face's plane beyond float32 rounding of the visibility's own test


# the light's condition number and a streamed problem's mirror neighbours use at most this many
# rows, drawn at random: on two dense scans (283k and 294k rows) the condition number from 200k
# rows is within 0.3 % of all rows'
CONDITION_ROWS = 200_000


def diffuse_shading(prep: Prepared, est: Estimate) -> np.ndarray:
    """(F, 3) each face's diffuse shading under the estimate's light, as its solve shaded it.

    The reported light holds a sun the estimate used (``info['sun']``, ``used``) projected to
    its SH order, where the delta rings and its shadows blur; the solve shaded the faces with
    the sun's exact shadowed column (:func:`estimator.light.sun.sun_shadings`). So the sun is
    taken back out of the SH light and its columns, kept on ``prep.visibility`` per direction,
    added at its reported irradiance. Otherwise C . x of the SH light."""
    sun = est.info.get("sun")
    if not (isinstance(sun, dict) and sun.get("used") and "irradiance" in sun):
        return prep.shading(est.light)
    sources = [sun] + list(sun.get("others", []))
    directions = np.array([s["direction"] for s in sources], dtype=float)
    irradiance = np.array([s["irradiance"] for s in sources], dtype=float)
    projected = prep.model.unknown_from_radiance(sh.project_directional(sh.order_of(est.light.shape[0]),
                                                                        directions, irradiance))
    coat_ior = est.config.coat_ior if sun.get("through_coat") else None
    key = ("sun columns", directions.tobytes(), coat_ior)   # the shadow function is the mesh's own
    columns = prep.visibility.derived.get(key)
    if columns is None:
        columns = sun_shadings(prep.data.mesh, prep.caster, directions, coat_ior)
        prep.visibility.derived[key] = columns
    return prep.shading(est.light - projected) + columns @ irradiance


def observation_residuals(prep: Prepared, est: Estimate) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 3) residuals of the kept observations under the estimate, (N,) their colour
    norms relative to the exposure level (:func:`estimator.solvers.robust.relative_residuals`), and
    (N, 3) each row's diffuse shading (:func:`diffuse_shading`)."""
    obs = prep.obs
    shade = diffuse_shading(prep, est)[obs.face]
    predicted = est.diffuse[obs.face] * shade + est.specular[obs.face] * prep.gloss(est.light)
    return obs.rgb - predicted, relative_residuals(obs.rgb, predicted), shade


def light_condition(prep: Prepared, est: Estimate, rows: np.ndarray) -> float:
    """Largest condition number over channels of the light's least-squares system with the
    albedos fixed (rows: (N,) bool, the observations used), sqrt of the normal matrix's
    eigenvalue ratio, from at most :data:`CONDITION_ROWS` of them, drawn at random (seed 0)."""
    index = np.nonzero(rows)[0]
    if len(index) > CONDITION_ROWS:
        index = np.sort(np.random.default_rng(0).choice(index, CONDITION_ROWS, replace=False))
    gram = [0.0] * 3
    for start in range(0, len(index), ROW_CHUNK):   # in chunks: no (N, M) temporaries
        part = index[start:start + ROW_CHUNK]
        face = prep.obs.face[part]
        c_rows, d_rows = prep.diffuse_rows(face), prep.specular_rows(part)
        for k in range(3):
            jac = est.diffuse[face, k, None] * c_rows + est.specular[face, k, None] * d_rows
            gram[k] = gram[k] + jac.T @ jac
    return max(1.0, *(normal_condition(g) for g in gram))


def normal_condition(gram: np.ndarray) -> float:
    """Condition number of a least-squares system from its normal matrix ``gram`` (M, M):
    sqrt of the ratio of its extreme eigenvalues; infinite where the smallest is within the
    eigensolver's rounding of the largest (machine epsilon of it, a condition number of about
    7e7, above :data:`ILL_CONDITIONED`): there the system is singular as far as its normal
    matrix can tell, and the ratio of two rounding errors would read as a finite number."""
    eig = np.linalg.eigvalsh(gram)
    if eig[-1] <= 0 or eig[0] <= eig[-1] * np.finfo(float).eps:
        return float("inf")
    return float(np.sqrt(eig[-1] / eig[0]))


def _row_views(obs) -> np.ndarray:
    """(N,) the view of each observation (all view 0 when the observations do not say)."""
    return obs.view if obs.view is not None else np.zeros(len(obs.face), dtype=np.int64)


def reflected_rows(prep: Prepared, labels: np.ndarray, residual: np.ndarray, relative: np.ndarray,
                   estimated: np.ndarray, rows: np.ndarray, threshold: float) -> np.ndarray:
    """Which of the given rows a reflection the model lacks explains rather than a fault of their view.

    A highlight is a property of the scene: wherever a view's mirror direction about a face's
    normal meets a bright light, the face is brighter than the model predicts if the model
    lacks that reflection, and darker if it predicts a highlight that is not there, in every
    view. Glare, an occluder or a wrong pose belong to one view. A row counts as reflected
    when the row of another view nearest to it in mirror direction, on a face of the same
    estimated group (the same material, on an object that mixes matte and glossy parts; any
    estimated face where the estimate groups none, as a per-face method), is an outlier too
    (relative residual above ``threshold``) with a residual of the same sign. The nearest row,
    not a vote of several: a sharp light's highlight spans a few degrees of mirror direction,
    and the next rows out already miss it.

    labels : (F,) the estimate's group per face (-1: none). rows : (R,) int indices into the
    observations; residual (N, 3), relative (N,), estimated (N,) bool per observation.
    Returns (R,) bool.
    """
    obs = prep.obs
    view = _row_views(obs)
    pool = np.nonzero(estimated)[0]
    if len(pool) > CONDITION_ROWS:
        pool = np.sort(np.random.default_rng(0).choice(pool, CONDITION_ROWS, replace=False))
    if len(rows) == 0 or len(pool) == 0 or obs.num_views < 2:
        return np.zeros(len(rows), bool)
    # a face's material group: its label where the label groups faces, else one group for all
    sizes = np.bincount(labels[labels >= 0], minlength=max(int(labels.max(initial=-1)) + 1, 1))
    face_group = np.where((labels >= 0) & (sizes[np.maximum(labels, 0)] > 1), labels, -1)

    def point(index: np.ndarray) -> np.ndarray:
        """(n, 4) mirror direction and 4 x group of the rows ``index``: groups 4 apart lie
        farther than any two unit vectors (chord <= 2), so a nearest row shares the group."""
        normal = prep.data.mesh.face_normals[obs.face[index]]
        out = obs.view_dir[index]
        mirror = 2.0 * np.sum(normal * out, axis=1, keepdims=True) * normal - out
        return np.column_stack([mirror, 4.0 * face_group[obs.face[index]]])

    query = point(rows)
    # scipy's k-d tree per view (a view's own rows crowd the nearest mirror directions): the
    # nearest row of any other view (chord distance orders as the angle)
    best = np.full(len(rows), np.inf)
    first = np.zeros(len(rows), dtype=np.int64)
    for v in np.unique(view[pool]):
        mine = pool[view[pool] == v]
        d, i = cKDTree(point(mine)).query(query, k=1)
        closer = (d < best) & (view[rows] != v)
        best[closer], first[closer] = d[closer], mine[i[closer]]
    found = np.isfinite(best) & (face_group[obs.face[first]] == face_group[obs.face[rows]])
    same_sign = np.sign(residual[first].sum(axis=1)) == np.sign(residual[rows].sum(axis=1))
    return found & same_sign & (relative[first] > threshold)


def shadow_edge_rows(prep: Prepared, est: Estimate, rows: np.ndarray, shade: np.ndarray) -> np.ndarray:
    """Which of the given rows the shadow on their reflection explains rather than a fault of their view.

    The paper's model (and the defiltered one) shades a face's reflection by its visibility
    along the mirror direction r alone, a yes-or-no stand-in for the visibility across the
    reflection's lobe. Where the object shadows part of the lobe, the true reflection lies
    anywhere between none and the unshadowed one, and the error shows in the one view whose
    mirror direction falls there: the rows of other views nearest in mirror direction lie on
    other faces with other shadows, so the mirror test (:func:`reflected_rows`) cannot vouch
    for it. A row counts as explained when both hold:

    * its face is shadowed by the object in some direction above its plane within 90 degrees
      of r (the widest lobe; a face open to its whole hemisphere there has no such edge);
    * its colour lies within ``GROSS_RESIDUAL`` of the exposure level of the segment between
      the two bounds: the diffuse term alone, and the diffuse term plus the unshadowed
      reflection h(r).

    Models that integrate the visibility over their lobe (``shadow_along_mirror`` False)
    explain nothing here. rows : (R,) int indices into the observations; shade : (N, 3) each
    observation's diffuse shading C . x. Returns (R,) bool.
    """
    obs = prep.obs
    if not prep.model.shadow_along_mirror or len(rows) == 0:
        return np.zeros(len(rows), bool)
    face, mirror = obs.face[rows], prep.row_mirrors(rows)
    low = est.diffuse[face] * shade[rows]
    span = est.specular[face] * prep.model.unshadowed_specular_shading(mirror, est.light)
    offset = obs.rgb[rows] - low
    t = np.clip(np.sum(offset * span, axis=1) / np.maximum(np.sum(span * span, axis=1), 1e-300), 0.0, 1.0)
    near = np.linalg.norm(offset - t[:, None] * span, axis=1) / exposure_level(obs.rgb) <= GROSS_RESIDUAL
    return near & _shadowed_near_mirror(prep, face, mirror)


def _shadowed_near_mirror(prep: Prepared, face: np.ndarray, mirror: np.ndarray, cells: int = 4_000_000) -> np.ndarray:
    """(R,) bool: face (R,) is hidden by the object from some sample direction above its plane
    (by more than :data:`PLANE_MARGIN`) within 90 degrees of its mirror direction (R, 3); in
    blocks of rows of at most ``cells`` (row, direction) pairs."""
    directions = prep.sampling.directions
    normals = prep.data.mesh.face_normals
    block = max(1, cells // len(directions))
    out = np.zeros(len(face), bool)
    for lo in range(0, len(face), block):   # blocks bound the (block, K) masks for many rows
        f, r = face[lo:lo + block], mirror[lo:lo + block]
        hidden = (normals[f] @ directions.T > PLANE_MARGIN) & ~prep.visibility.unpack(f)
        out[lo:lo + block] = np.any(hidden & (r @ directions.T > 0), axis=1)
    return out


def _add_neighbour_shares(views: list[dict], prep: Prepared) -> None:
    """Give each view's summary ``neighbour_gross_share`` and ``neighbour_exposure``: the median
    gross-error share and exposure of the NEIGHBOUR_VIEWS views nearest to it in direction from
    the object's centre. A model misfit that depends on the viewing direction (a reflection the
    model lacks) raises the share, and moves the exposure, of neighbouring views together;
    glare, an occluder, a wrong pose or a view's own exposure moves one view's alone."""
    if len(views) != len(prep.data.views) or len(views) < NEIGHBOUR_VIEWS + 1:
        return
    centre = prep.data.mesh.vertices.mean(axis=0)
    dirs = np.array([v.camera.center for v in prep.data.views]) - centre
    dirs /= np.maximum(np.linalg.norm(dirs, axis=1, keepdims=True), 1e-300)
    shares = np.array([np.nan if v["gross_share"] is None else v["gross_share"] for v in views])
    exposures = np.array([np.nan if v["exposure"] is None else v["exposure"] for v in views])
    cosines = dirs @ dirs.T
    np.fill_diagonal(cosines, -np.inf)
    nearest = np.argsort(-cosines, axis=1)[:, :NEIGHBOUR_VIEWS]
    for v, near in zip(views, nearest):
        known = shares[near][np.isfinite(shares[near])]
        v["neighbour_gross_share"] = float(np.median(known)) if len(known) else None
        known = exposures[near][np.isfinite(exposures[near])]
        v["neighbour_exposure"] = float(np.median(known)) if len(known) else None


def diagnose(prep: Prepared, est: Estimate, view_names: list[str]) -> tuple[dict, dict[str, np.ndarray]]:
    """Trust diagnostics of an estimate.

    Returns
    -------
    summary : JSON-ready dict: ``views`` (per view: observations, relative residual
        (median), outlier share, gross-error share, exposure relative to the views'
        (:func:`estimator.pipeline.exposure.view_gains`, geometric mean over channels), and the
        median gross-error share and exposure of its nearest views),
        ``residual`` (median relative residual, robust scale),
        ``light_condition``, ``albedo_relative_se`` (quantiles over estimated faces),
        ``outlier_share``.
    faces : per-face arrays: ``observations`` (F,) kept rows, ``albedo_se`` (F, 3)
        standard error of the diffuse albedo with the light fixed (inf where unseen).
    """
    obs = prep.obs
    f = obs.num_faces
    residual, relative, shade = observation_residuals(prep, est)
    estimated = est.observed[obs.face]
    scale, outlier = _outliers(relative, estimated)
    gross = estimated & (relative > GROSS_RESIDUAL)
    gross_rows = np.nonzero(gross)[0]
    fault = gross.copy()
    fault[gross_rows[reflected_rows(prep, est.labels, residual, relative, estimated, gross_rows,
                                    OUTLIER_SIGMAS * max(scale, MIN_OUTLIER_SCALE))]] = False
    fault_rows = np.nonzero(fault)[0]
    fault[fault_rows[shadow_edge_rows(prep, est, fault_rows, shade)]] = False
    views = []
    view = _row_views(obs)
    # each view's exposure relative to the others (geometric mean over channels), a figure: a
    # glossy object's view-dependent reflection moves it too (estimator.pipeline.exposure)
    exposure = np.exp(np.log(view_gains(obs)).mean(axis=1)) if obs.view is not None else np.ones(obs.num_views)
    for v in range(obs.num_views):
        sel = (view == v) & estimated
        views.append({"view": view_names[v] if v < len(view_names) else str(v), "observations": int(sel.sum()),
                      "residual": float(np.median(relative[sel])) if sel.any() else None,
                      "outlier_share": float(outlier[sel].mean()) if sel.any() else None,
                      "gross_share": float(gross[sel].mean()) if sel.any() else None,
                      "fault_share": float(fault[sel].mean()) if sel.any() else None,
                      # None for a view without rows (rowless or black): the fit's 1 there is no figure
                      "exposure": float(exposure[v]) if np.any(view == v) else None})
    _add_neighbour_shares(views, prep)
    # standard error of each face's diffuse albedo with the light fixed: sigma / sqrt(sum shade^2)
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma = noise_level(_fitted_columns(prep, est, shade), residual, estimated, est.labels[obs.face])
        albedo_se = 1.0 / np.sqrt(_precision(obs.face, f, shade, outlier, sigma, obs.radiance_se))
        rel_se = np.linalg.norm(albedo_se, axis=1) / np.linalg.norm(est.diffuse + est.specular, axis=1)
    counts = np.bincount(obs.face, minlength=f)
    good = est.observed & np.isfinite(rel_se)
    summary = {
        "residual": {"median_relative": float(np.median(relative[estimated])) if estimated.any() else None,
                     "robust_scale": scale},
        "outlier_share": float(outlier[estimated].mean()) if estimated.any() else 0.0,
        "light_condition": _finite_or_none(light_condition(prep, est, estimated & ~outlier)
                                           if (estimated & ~outlier).any() else float("inf")),
        "albedo_relative_se": {q: float(np.quantile(rel_se[good], p)) for q, p in
                               (("median", 0.5), ("p90", 0.9), ("max", 1.0))} if good.any() else None,
        "observations_per_face": {"median": float(np.median(counts[est.observed])) if est.observed.any() else 0.0,
                                  "min": int(counts[est.observed].min()) if est.observed.any() else 0},
        "views": views,
    }
    return summary, {"observations": counts.astype(np.int64), "albedo_se": albedo_se}


def _outliers(relative: np.ndarray, estimated: np.ndarray) -> tuple[float, np.ndarray]:
    """(robust scale of the rows of estimated faces, (N,) bool outlier rows)."""
    scale = robust_scale(relative[estimated]) if estimated.any() else 0.0
    return scale, relative > OUTLIER_SIGMAS * max(scale, MIN_OUTLIER_SCALE)


def _precision(face: np.ndarray, num_faces: int, rows: np.ndarray, outlier: np.ndarray,
               sigma: np.ndarray, radiance_se: np.ndarray | None = None) -> np.ndarray:
    """(F, 3) precision of a per-face albedo with the light fixed, fitted by least squares to its
    inlier rows (rows (N, 3): the albedo's coefficient x in each observation): the inverse of
    sigma^2 / sum x^2 (``sigma`` (3,) the rows' noise level per channel, :func:`noise_level`)
    plus, where every row of a face holds one radiance unmixed from shared pixels with standard
    error s (``radiance_se`` (F, 3), :attr:`Observations.radiance_se`; None: none), that error
    carried into the fit, s^2 (sum x)^2 / (sum x^2)^2. 0 where a face has no row."""
    inlier = ~outlier
    info = np.stack([np.bincount(face, rows[:, k] ** 2 * inlier, minlength=num_faces) for k in range(3)], 1)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        variance = np.maximum(sigma ** 2, 1e-300)[None] / info
        if radiance_se is not None:
            total = np.stack([np.bincount(face, rows[:, k] * inlier, minlength=num_faces) for k in range(3)], 1)
            variance = variance + radiance_se ** 2 * (total / info) ** 2
        return np.where(info > 0, np.nan_to_num(1.0 / variance), 0.0)


def noise_level(columns: list[np.ndarray], residual: np.ndarray, estimated: np.ndarray,
                group: np.ndarray) -> np.ndarray:
    """(3,) robust noise level per channel: 1.4826 x the median absolute residual (N, 3) of the
    ``estimated`` rows (N,) bool, each divided by sqrt(1 - h), h its leverage in the fit of its
    group's albedos (``group`` (N,)): per channel, one albedo per column of ``columns`` (one or
    two (N, 3) arrays: the diffuse shading, the specular gloss or both), h = x^T (sum over the
    group of x x^T)^-1 x for the row's coefficients x. A fit of p albedos from n rows leaves
    residuals of variance sigma^2 (1 - h), summing to (n - p) sigma^2: a row a fit interpolates
    (h = 1, residual 0 whatever the noise) says nothing of the noise and is left out, so a mesh
    seen once per face does not claim a noise of 0 and its faces' albedos exact beside faces
    seen more often. Where every row is interpolated (an exact fit, which the run warns is
    underdetermined), the residuals as they are, near 0: that fit's errors are unknown.
    Infinite without an estimated row."""
    index = np.nonzero(estimated)[0]
    if not len(index):
        return np.full(3, np.inf)
    _, inverse = np.unique(group[index], return_inverse=True)

    def summed(values):   # over each row's group, back on its rows
        return np.bincount(inverse, values)[inverse]

    sigma = np.full(3, np.inf)
    for k in range(3):
        x = [c[index, k] for c in columns]
        with np.errstate(divide="ignore", invalid="ignore"):
            if len(x) == 1:
                leverage = x[0] ** 2 / summed(x[0] ** 2)
            else:
                a, b, c = summed(x[0] ** 2), summed(x[0] * x[1]), summed(x[1] ** 2)
                det = a * c - b * b
                # otherwise the columns are collinear in the group, or one is 0 (or a * c underflows)
                whole = (a * c > 0) & (det > 1e-12 * a * c)
                leverage = np.where(whole, (c * x[0] ** 2 - 2 * b * x[0] * x[1] + a * x[1] ** 2) / det,
                                    (x[0] ** 2 + x[1] ** 2) / (a + c))
        free = np.isfinite(leverage) & (leverage < 1.0 - 1e-9)   # a row of non-finite coefficients says nothing
        if not free.any():
            free, leverage = np.ones(len(index), bool), np.zeros(len(index))
        sigma[k] = 1.4826 * np.median(np.abs(residual[index[free], k]) / np.sqrt(1.0 - leverage[free]))
    return sigma


def _fitted_columns(prep: Prepared, est: Estimate, shade: np.ndarray,
                    gloss: np.ndarray | None = None) -> list[np.ndarray]:
    """The coefficients (N, 3) of the albedos each row's group fits: the diffuse shading
    ``shade``, the specular ``gloss`` (None: computed here), or both (``est.config.components``). A method whose free
    faces share one specular (``info['own_specular_groups']``: the labels below it fit their
    own) gives those rows no specular column: one unknown over all of them moves no row's fit."""
    components = est.config.components
    columns = [] if components == "specular" else [shade]
    if components != "diffuse":
        gloss = prep.gloss(est.light) if gloss is None else gloss
        own = est.info.get("own_specular_groups")
        if own is not None and components == "both":
            gloss = gloss * (est.labels[prep.obs.face] < own)[:, None]
        columns.append(gloss)
    return columns


def albedo_precision(prep: Prepared, est: Estimate) -> tuple[np.ndarray, np.ndarray]:
    """(F, 3) precisions of the diffuse and of the specular albedo of each face with the light
    fixed (each as if the other were known), from the estimate's own residuals."""
    residual, relative, shade = observation_residuals(prep, est)
    estimated = est.observed[prep.obs.face]
    _, outlier = _outliers(relative, estimated)
    face, f = prep.obs.face, prep.obs.num_faces
    gloss = prep.gloss(est.light)
    sigma = noise_level(_fitted_columns(prep, est, shade, gloss), residual, estimated, est.labels[face])
    unmixed = prep.obs.radiance_se
    return (_precision(face, f, shade, outlier, sigma, unmixed),
            _precision(face, f, gloss, outlier, sigma, unmixed))


def _finite_or_none(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def warnings_for(est: Estimate) -> list[str]:
    """What makes an estimate untrustworthy without ground truth, one line each."""
    out = []
    info = est.info
    unestimated = info.get("unestimated") or {}
    if unestimated:
        out.append(f"{sum(unestimated.values())} face(s) left unestimated, their albedo not determined by the data: "
                   + ", ".join(f"{n} {reason}" for reason, n in unestimated.items())
                   + " (face_stats 'unestimated_reason'; reports treat them as missing)")
    dof = info.get("degrees_of_freedom")
    if dof and dof["unknowns"] >= dof["observations"]:
        out.append(f"underdetermined: {dof['unknowns']} unknowns for {dof['observations']} observations "
                   "(the solve fits exactly whatever the truth; add views)")
    unkept = info.get("faces_without_kept_views", 0.0)
    if unkept > MAX_UNKEPT:
        out.append(f"{100 * unkept:.0f} % of the faces have no observation within min_cos_view of their normal")
    trust = info.get("trust")
    if not trust:
        return out
    cond = trust["light_condition"]
    if cond is None or cond > ILL_CONDITIONED:
        out.append(f"ill-conditioned: the light's normal equations have condition number "
                   f"{'infinite' if cond is None else f'{cond:.3g}'} (parts of the light are not determined by "
                   "the views; add views or lower sh_order)")
    # a view's share of gross errors no reflection explains (older runs: all its gross errors),
    # against all views' and against the gross errors of the views beside it
    faults = [(v, v.get("fault_share", v.get("gross_share"))) for v in trust["views"]]
    typical = float(np.median([s for _, s in faults if s is not None] or [0.0]))
    bad = [(v, share) for v, share in faults if share is not None
           and share > max(OUTLIER_VIEW_SHARE, OUTLIER_VIEW_FACTOR * typical,
                           OUTLIER_VIEW_FACTOR * (v.get("neighbour_gross_share") or 0.0))
           and share * v["observations"] >= OUTLIER_VIEW_ROWS]
    for v, share in bad:
        exposure = f"; its exposure is {v['exposure']:.2f}x the views' (view_gains divides out auto-exposure)" \
            if v.get("exposure") is not None else ""
        out.append(f"outlier view {v['view']}: {100 * share:.1f} % of its observations are off by over "
                   f"{100 * GROSS_RESIDUAL:.0f} % of the exposure level where other views reflecting the same "
                   f"directions fit (typical view {100 * typical:.1f} %): glare, an occluder or a wrong pose? "
                   f"(pose refinement, pose_rounds, corrects poses){exposure}")
    if not info.get("view_gains"):
        out += _exposure_warnings(trust["views"])
    se = trust.get("albedo_relative_se")
    if se and se["median"] > IMPRECISE_ALBEDO:
        out.append(f"imprecise albedos: the median face's own observations fix its albedo only to ±"
                   f"{100 * se['median']:.0f} % (one standard error, the light fixed), beyond the ±"
                   f"{100 * IMPRECISE_ALBEDO:.0f} % the reports score: noise, few views, or colours that a glossy "
                   "coat's reflection dominates (dark albedos under a coat)")
    median = trust["residual"]["median_relative"]
    if median is not None and median > HIGH_RESIDUAL:
        out.append(f"high residual: the estimate re-predicts its observations with a median relative error of "
                   f"{100 * median:.0f} % (the model does not explain these images)")
    return out


def _exposure_warnings(views: list[dict]) -> list[str]:
    """Warnings for views whose exposure is off against their neighbours' (:data:`EXPOSURE_SIGMAS`):
    a view whose gain the two-way fit of the faces' colours sets apart (auto-exposure, another
    shutter or aperture). Its colours disagree with every other view's by that factor; the
    solve follows it where it gives a face's lowest colours, so the gross-error share of the
    outlier-view check does not single it out."""
    known = [v for v in views if v.get("exposure") and v.get("neighbour_exposure")]
    if len(known) <= NEIGHBOUR_VIEWS:
        return []
    diff = np.log([v["exposure"] / v["neighbour_exposure"] for v in known])
    scale = robust_scale(np.abs(diff - np.median(diff)), floor=1e-12)
    bound = max(np.log1p(IMPRECISE_ALBEDO), EXPOSURE_SIGMAS * scale)
    return [f"view {v['view']} is exposed {v['exposure'] / v['neighbour_exposure']:.2f}x its neighbouring views "
            f"(auto-exposure, or another shutter or aperture?): its colours disagree with theirs by that factor "
            "throughout; view_gains=true divides each view's gain out" for v, d in zip(known, diff) if abs(d) > bound]
