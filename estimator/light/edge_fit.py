"""The light from albedo edges: a Retinex prior on the mesh, solved in the log domain.

Neighbouring faces receive nearly the same light, so wherever their albedos agree the
ratio of their diffuse radiances is the ratio of their shadings, whatever the albedo.
Albedo changes are sparse (region boundaries, texture edges); a robust loss lets them
go. With the shading of face f written as s_f = C_f . L (C the reflection model's
diffuse rows, with the shadow function; L the light, unit DC per channel), the light
minimises, per channel,

    sum_edges  rho( (l_i - l_j) - (log s_i - log s_j) )
  + sum_{f in region r}  rho( l_f - log s_f - a_r )          (optional uniform regions)
  + ridge * n * sum_lm (l (l + 1))^2 L_lm^2

with l_f the log diffuse radiance of face f and a_r the log albedo of region r. The
first term is the whole prior for textured objects (no region needed); the second ties
far-apart faces of one uniform region to one albedo. Gauss-Newton on the IRLS weights of
the chosen M-estimator (:mod:`estimator.solvers.robust`), with steps halved until every shading
stays positive. The normal equations are formed without the Jacobian: the edges' part is
g^T L_w g with L_w the weighted graph Laplacian of the face adjacency and g the log
shading's gradient per face, so time and memory grow with faces x coefficients^2.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ..core.edge_graph import EdgeGraph
from ..core.errors import InputError
from ..core.gauge import unit_dc
from ..core.reductions import group_quantile
from ..core.settings import Section
from ..solvers import robust

# a Gauss-Newton step that changes no usable face's log shading, nor any region's log albedo,
# by more than this ends the fit. Measured on the random family's 40 development seeds (median
# PSNR; the change of its sum over the seeds against 1e-3; cost):
#   1e-3: 33.78 dB;
#   3e-4: 33.78 dB, +0.45 dB, 1.5 times the steps of 1e-3 (on one real-light estimate);
#   1e-5 with up to 100 steps: 33.92 dB, -0.95 dB, every estimate 36 % slower in sum.
SHADING_TOLERANCE = 1e-3

# the light's block of the Gauss-Newton matrix (faces x coefficients^2 to form, most of the
# fit's cost) is kept from the last step that formed it while each step since changed no
# usable face's log shading, nor any region's log albedo, by more than this: the block is a sum
# over faces of their inverse shadings squared times IRLS weights, so it has moved by a few per
# cent, and a step with it still solves for the exact gradient (the fit tends to the same
# light, in a few more steps). A step under SHADING_TOLERANCE ends the fit only when its block
# was fresh; the fit also ends when ``iterations`` run out or no step keeps every shading
# positive, whatever its block.
BLOCK_REUSE = 0.02


@dataclass
class EdgeFitConfig(Section):
    """The light from albedo edges (:func:`log_shading_fit`).

    Attributes
    ----------
    retinex_quantile : a face's diffuse radiance is this quantile of its colours over the
        views (low: a coat's highlights move with the view and rarely reach it). Measured on
        the random family's 40 development seeds (1000-1039, full size): 0.1 left the median
        PSNR (33.8 dB), the share of seeds with 90 % of faces within ±10 % (0.375) and the
        5th percentile (23.0 against 22.7 dB) as they are, seeds moving by up to 2 dB either
        way; 0.3 lost 1 dB of median on seeds 1000-1020.
    retinex_ridge : weight of the (l (l + 1))^2 penalty on the light, per row (a
        tie-breaker for coefficients the shading does not see).
    retinex_iterations : Gauss-Newton steps of the edge fit per channel.
    retinex_max_edges : a fit over more usable edges than this runs on this many drawn at
        random (seed 0) and on the region rows of their faces: a light of at most 3 x 121
        coefficients is determined many times over by 20,000 equations, while a dense scan's
        100k edges and more would cost time in proportion. At least the light's
        (sh_order + 1)^2 coefficients (the estimator's config checks it).
    """

    retinex_quantile: float = 0.2
    retinex_ridge: float = 1e-9
    retinex_iterations: int = 30
    retinex_max_edges: int = 20_000

    def check(self):
        return [
            (0 <= self.retinex_quantile <= 1, "retinex_quantile must lie in [0, 1]"),
            (self.retinex_ridge >= 0, "retinex_ridge must be >= 0"),
            (self.retinex_iterations >= 1, "retinex_iterations must be >= 1"),
            (self.retinex_max_edges >= 1, "retinex_max_edges must be >= 1"),
        ]


def _degrees(m: int) -> np.ndarray:
    """(m,) SH degree of each light column; columns past the last full order (a sun,
    :mod:`estimator.light.sun`) get degree 0, so the ridge leaves them free."""
    order = int(np.sqrt(m)) - 1
    sh_part = np.concatenate([np.full(2 * l + 1, l, dtype=float) for l in range(order + 1)])
    return np.concatenate([sh_part, np.zeros(m - len(sh_part))])


def usable_edges(edges: np.ndarray, usable: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Faces (E',) i and j of the edges (E, 2) whose two faces are usable ((F,) bool): the
    edges every fit and cost here runs over."""
    pair = usable[edges[:, 0]] & usable[edges[:, 1]]
    return edges[pair, 0], edges[pair, 1]


def edge_residuals(radiance: np.ndarray, shading: np.ndarray, edges: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """(E', C) log radiance ratio minus log shading ratio across the :func:`usable_edges`;
    radiance and shading (F, C), positive where usable."""
    i, j = usable_edges(edges, usable)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.log(radiance[i] / radiance[j]) - np.log(
            np.maximum(shading[i], 1e-300) / np.maximum(shading[j], 1e-300)
        )
    return ratio


def log_shading_fit(radiance: np.ndarray, c_matrix: np.ndarray, edges: np.ndarray, usable: np.ndarray,
                    labels: np.ndarray | None = None, initial: np.ndarray | None = None,
                    loss: str = "cauchy", ridge: float = EdgeFitConfig.retinex_ridge,
                    iterations: int = EdgeFitConfig.retinex_iterations,
                    indirect: np.ndarray | None = None,
                    max_edges: int = EdgeFitConfig.retinex_max_edges) -> tuple[np.ndarray, np.ndarray]:
    """Light and region albedos that explain the log radiance ratios of neighbouring faces.

    Parameters
    ----------
    radiance : (F, C) diffuse radiance of each face (linear, > 0 where ``usable``): C colour
        channels, each fitted apart (3, or one channel alone).
    c_matrix : (F, M) diffuse rows: the shading of face f under light L is c_matrix[f] @ L.
    edges : (E, 2) pairs of neighbouring faces.
    usable : (F,) bool, faces whose radiance enters the fit.
    labels : (F,) int uniform region of each face, -1 outside every region (None: edges only).
    initial : (M, C) starting light (None: DC only).
    loss : robust loss of :func:`estimator.solvers.robust.irls_weights` ('none' is least squares).
    ridge : weight of the (l (l + 1))^2 penalty on the light's coefficients, per row.
    iterations : Gauss-Newton steps per channel at most (stops earlier when a step moves no
        shading by more than :data:`SHADING_TOLERANCE`).
    indirect : (F, C) shading added to C L (light the object reflects onto itself,
        :mod:`estimator.light.indirect`); it fixes the light's scale, so the DC is fitted too
        (each channel in the unit of its median usable radiance, :func:`radiance_unit`) and the
        ridge weighs the coefficients over the DC (the shape, as without it). A term nil on
        every usable face (a convex object) fixes no scale and is dropped: unit DC.
    max_edges : beyond this many usable edges the fit runs on this many drawn at random
        (seed 0) and on the region rows of their faces only; a region none of whose faces is
        drawn takes the median of its faces' log radiance over log shading under the light.

    Returns
    -------
    light : (M, C) light with unit DC per channel (the scale is a gauge), or at its own
        scale with an ``indirect`` term that is not nil.
    region_albedo : (R, C) albedo of each region (R = labels.max() + 1; (0, C) without labels).
    """
    f, m = c_matrix.shape
    if radiance.ndim != 2 or radiance.shape[0] != f or radiance.shape[1] < 1 or usable.shape != (f,):
        raise InputError(f"radiance must be (F, C) and usable (F,) with F = {f} faces of c_matrix, "
                         f"got {radiance.shape} and {usable.shape}")
    if edges.ndim != 2 or edges.shape[1] != 2 or (len(edges) and (edges.min() < 0 or edges.max() >= f)):
        raise InputError(f"edges must be (E, 2) face indices below {f}, got shape {edges.shape}")
    channels = radiance.shape[1]
    if initial is not None:
        initial = np.asarray(initial, dtype=float)
        if initial.ndim != 2 or initial.shape[1] != channels:
            raise InputError(f"initial must be (M, C) with the C = {channels} channels of radiance, "
                             f"got {initial.shape}")
    if indirect is not None and np.shape(indirect) != radiance.shape:
        raise InputError(f"indirect must be (F, C) like radiance {radiance.shape}, got {np.shape(indirect)}")
    labels = np.full(f, -1, dtype=np.int64) if labels is None else np.asarray(labels, dtype=np.int64)
    if labels.shape != (f,):
        raise InputError(f"labels must be (F,) = ({f},), got {labels.shape}")
    # a face no light of these columns reaches (no sky seen, nothing added) cannot be explained
    reached = c_matrix[:, 0] > 0
    usable = usable & (reached if indirect is None else reached | np.all(indirect > 0, axis=1))
    if indirect is not None and not np.any(np.asarray(indirect)[usable] > 0):
        # nil on every face of the fit (a convex object reflects nothing onto itself), the term
        # fixes no scale: the DC stays the gauge. Fitted as free, it drifted towards 0 and the
        # fit lost the shading's jumps across a cube's creases (15.6 -> 59 dB without it)
        indirect = None
    i, j = usable_edges(edges, usable)
    member = np.nonzero(usable & (labels >= 0))[0]
    group = labels[member]
    regions = int(labels.max()) + 1 if len(member) else 0
    if len(i) + len(member) == 0:
        raise InputError("the light fit needs two usable neighbouring faces or a uniform region")
    unit = radiance_unit(radiance, usable) if indirect is not None else np.ones(channels)
    light = np.zeros((m, channels)) if initial is None else np.array(initial[:m], dtype=float)
    if initial is None:
        light[0] = unit     # a DC of 1 in the fit's unit
    if indirect is None:
        light = unit_dc(light)[0]
    with np.errstate(divide="ignore"):
        log_radiance = np.log(np.where(usable[:, None], radiance, 1.0))
    faces = np.arange(f)   # the faces the fit reads
    if len(i) > max_edges:
        drawn = np.sort(np.random.default_rng(0).choice(len(i), max_edges, replace=False))
        touched = np.zeros(f, dtype=bool)
        touched[i[drawn]] = touched[j[drawn]] = True
        faces = np.nonzero(touched)[0]
        compact = np.full(f, -1, dtype=np.int64)
        compact[faces] = np.arange(len(faces))
        i, j = compact[i[drawn]], compact[j[drawn]]
        group, member = group[touched[member]], compact[member[touched[member]]]
    penalty = ridge * (len(i) + len(member)) * (_degrees(m)[1:] * (_degrees(m)[1:] + 1)) ** 2
    albedo = np.zeros((regions, channels))
    graph = EdgeGraph.of(i, j, len(faces))
    rows = c_matrix if len(faces) == f else c_matrix[faces]
    # the unknowns' columns (the DC is the gauge without ``indirect``), copied once for the
    # channels' Gauss-Newton products
    columns = np.ascontiguousarray(rows[:, (1 if indirect is None else 0):])
    by_region = _region_pattern(member, group, regions, len(faces))
    for c in range(channels):
        extra = None if indirect is None else indirect[faces, c] / unit[c]
        fitted, albedo[:, c] = _fit_channel(log_radiance[faces, c] - np.log(unit[c]), rows, columns, graph, member,
                                            group, by_region, regions, light[:, c] / unit[c], usable[faces], loss,
                                            penalty, iterations, extra)
        light[:, c] = fitted * unit[c]
    missing = np.bincount(group, minlength=regions) == 0
    if missing.any():   # regions whose faces were not drawn: the median under the fitted light
        tied = np.nonzero(usable & missing[np.maximum(labels, 0)] & (labels >= 0))[0]
        shade = np.maximum(c_matrix[tied] @ light + (0.0 if indirect is None else indirect[tied]), 1e-300)
        medians = group_quantile(labels[tied], log_radiance[tied] - np.log(shade), regions, 0.5, interpolate=True)
        albedo[missing] = medians[missing]
    return light, np.exp(albedo)


def radiance_unit(radiance: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """(C,) the unit a fit with an additive shading runs in: each channel's median radiance over
    the ``usable`` faces (1 where that is not positive). With the indirect term the light has the
    radiance's unit, and the fit's start (a DC of 1) and its steps along the light's scale, which
    only the faint indirect term fixes, depend on that unit: images scaled by 1e-5 started a light
    10^10 times too bright, whose shape no step moved. In this unit (the radiance, the indirect
    term, linear in it, and a given start divided by it) the fit is the same for images of any
    scale, and its light is scaled back."""
    level = np.ones(radiance.shape[1])
    for c in range(radiance.shape[1]):
        values = radiance[usable, c]
        values = values[np.isfinite(values)]
        if len(values):
            level[c] = np.median(values)
    return np.where(level > 0, level, 1.0)


def _fit_channel(ell, c_matrix, columns, graph, member, group, by_region, regions, light, usable, loss, penalty,
                 iterations, extra=None):
    """One channel's Gauss-Newton fit. Unknowns: the light's coefficients from ``first`` on
    (1: the DC is the gauge; 0 with an additive ``extra`` shading, which fixes the scale)
    and the regions' log albedos; ``columns`` is ``c_matrix[:, first:]``, contiguous;
    ``by_region`` the region rows' pattern (:func:`_region_pattern`)."""
    first = 1 if extra is None else 0
    extra = np.zeros(len(ell)) if extra is None else extra
    penalty = np.concatenate([[0.0], penalty]) if first == 0 else penalty
    shade = c_matrix @ light + extra
    if np.any(shade[usable] <= 0):
        light = np.zeros_like(light)
        light[0] = 1.0
        shade = c_matrix @ light + extra
    log_shade = np.log(np.maximum(shade, 1e-300))
    alpha = _region_medians((ell - log_shade)[member], group, regions) if regions else np.zeros(0)
    k = len(light) - first
    n = k + regions
    block, change = None, np.inf
    for _ in range(iterations if n else 0):   # n = 0: a DC-only light with no regions, nothing to fit
        residual = _residuals(ell, log_shade, graph, member, group, alpha)
        size = np.abs(residual)
        weights = robust.irls_weights(size, loss, robust.robust_scale(size))
        # the log shading's gradient is columns / shade per face; 0 on faces outside the fit
        # (their shading may be 0: a face that sees no sky), which no edge or region row reads
        inverse_shade = np.where(usable, 1.0 / np.where(usable, shade, 1.0), 0.0)
        fresh = block is None or change > BLOCK_REUSE or change < SHADING_TOLERANCE
        if fresh:
            block = _light_block(columns, inverse_shade, graph, member, weights)
        normal, gradient = _normal_equations(columns, inverse_shade, graph, member, group, regions, weights,
                                             residual, block, by_region)
        # the ridge on the light relative to its DC: with an ``extra`` shading the scale is
        # free, and a ridge on the coefficients themselves would shrink the whole light until
        # the (faint) extra term is as bright as the direct, bending its shape
        relative = penalty if first else penalty / max(light[0] ** 2, 1e-300)
        normal[:k, :k] += np.diag(relative)
        gradient[:k] += relative * light[first:]
        step = -np.linalg.solve(normal + 1e-12 * np.trace(normal) / n * np.eye(n), gradient)
        t = 1.0
        while t > 1e-4:
            trial = light.copy()
            trial[first:] += t * step[:k]
            trial_shade = c_matrix @ trial + extra
            if np.all(trial_shade[usable] > 0):
                break
            t *= 0.5
        else:
            break  # no positive step: keep the light
        trial_log = np.log(np.maximum(trial_shade, 1e-300))
        change = max(float(np.max(np.abs(trial_log - log_shade)[usable], initial=0.0)),
                     float(np.max(np.abs(t * step[k:]), initial=0.0)))
        light, shade, log_shade = trial, trial_shade, trial_log
        alpha = alpha + t * step[k:]
        if change < SHADING_TOLERANCE and fresh:
            break
    if regions:
        alpha = _region_levels(ell, log_shade, graph, member, group, regions, alpha, loss)
    return light, alpha


def _region_medians(values: np.ndarray, group: np.ndarray, regions: int) -> np.ndarray:
    """(R,) the median of each region's ``values`` (R',) (``group`` (R',) their regions): where
    the fit starts the regions' log albedos."""
    return group_quantile(group, values[:, None], regions, 0.5, interpolate=True)[:, 0]


def _region_levels(ell, log_shade, graph, member, group, regions, alpha, loss, iterations: int = 20) -> np.ndarray:
    """(R,) the regions' log albedos at their optimum under the final light, from ``alpha``:
    IRLS on the region rows alone, ``ell`` (F,) the log radiance and ``log_shade`` (F,) the final
    log shading.

    A Gauss-Newton step moves the log albedos by the linearised change of the log shading; a
    long step along the light's scale (nearly free where only the faint indirect term fixes it)
    changes the log shading by log(1 + t) and the albedos by -t, and the last step's remainder
    would stay in every region. Where the fit converged this moves them by less than its
    tolerance: a Gauss-Newton step that leaves the light still is this IRLS step. A region
    whose every row a redescending loss (Tukey's) rejects at ``alpha`` starts again from its
    median, as the fit started."""
    values = (ell - log_shade)[member]
    present = np.bincount(group, minlength=regions) > 0
    # one scale for the update: the robust scale of every residual, edges' and regions', at the final light
    scale = robust.robust_scale(np.abs(_residuals(ell, log_shade, graph, member, group, alpha)))
    for _ in range(iterations):
        weights = robust.irls_weights(np.abs(values - alpha[group]), loss, scale)
        total = np.bincount(group, weights, regions)
        mean = np.bincount(group, weights * values, regions) / np.where(total > 0, total, 1.0)
        updated = np.where(total > 0, mean, alpha)   # a region without a face in the fit keeps its value
        rejected = present & (total == 0)
        if rejected.any():
            updated[rejected] = _region_medians(values, group, regions)[rejected]
        moved = float(np.max(np.abs(updated - alpha), initial=0.0))
        alpha = updated
        if moved < SHADING_TOLERANCE:
            break
    return alpha


def _residuals(ell, log_shade, graph, member, group, alpha) -> np.ndarray:
    """(E' + R',) edge residuals (log radiance ratio minus log shading ratio) then region residuals."""
    edge = graph.difference(ell - log_shade)
    region = ell[member] - log_shade[member] - alpha[group] if len(member) else np.zeros(0)
    return np.concatenate([edge, region])


def _light_block(columns, inverse_shade, graph, member, weights) -> np.ndarray:
    """(k, k) the light coefficients' block of :func:`_normal_equations`' matrix: one sparse
    product and one (k, F) x (F, k) product, the scaling D applied to the sparse matrix's
    entries. Memory and time grow with faces x k^2, not edges x k^2."""
    faces, ne = len(inverse_shade), len(graph)
    on_diagonal = np.bincount(member, weights[ne:], faces) if len(member) else None   # summed per face
    return columns.T @ (graph.laplacian(weights[:ne], inverse_shade, on_diagonal) @ columns)


def _region_pattern(member, group, regions, faces) -> tuple[np.ndarray, sparse.csr_matrix]:
    """The order (R',) that puts per-member values in the region rows' matrix entries, and that
    (R, F) matrix's pattern: one entry per member face (R',), in its region's row. Formed once
    per fit and refilled at every step; for ``member`` sorted ascending and unique (as
    :func:`log_shading_fit` passes it) the refilled matrix is, array for array, the one built
    from the (group, member) pairs."""
    order = np.argsort(group, kind="stable")   # rows in turn, each row's faces ascending as ``member`` is
    indptr = np.concatenate([[0], np.cumsum(np.bincount(group, minlength=regions))])
    return order, sparse.csr_matrix((np.ones(len(member)), member[order], indptr), shape=(regions, faces))


def _normal_equations(columns, inverse_shade, graph, member, group, regions, weights, residual, block, by_region):
    """Gauss-Newton normal equations (J^T W J, J^T W r) of :func:`_residuals` with respect to
    the light coefficients and the regions' log albedos, without forming J; ``block`` (k, k):
    the light's block of J^T W J (:func:`_light_block`, formed by the caller, which keeps it
    while steps are small); ``by_region``: the region rows' pattern (:func:`_region_pattern`).

    The log shading's gradient per face is g = D c, ``columns`` c (F, k) the diffuse rows of
    the unknowns and D = diag(``inverse_shade``) (F,) (0 outside the fit). An edge's row is
    -(g_i - g_j) = -(B g)_e with B the (E', F) signed incidence of ``graph``
    (:class:`EdgeGraph`); a region row of face f in group r is [-g_f, -e_r]. The light's block
    is therefore c^T D (B^T W_e B + W_r) D c, W_r the region rows' weights on the diagonal.
    """
    k = columns.shape[1]
    faces = len(inverse_shade)
    ne = len(graph)
    w_edge, w_region = weights[:ne], weights[ne:]
    r_edge, r_region = residual[:ne], residual[ne:]
    normal = np.zeros((k + regions, k + regions))
    gradient = np.zeros(k + regions)
    normal[:k, :k] = block
    pulled = graph.gather(w_edge * r_edge)
    if len(member):
        pulled = pulled + np.bincount(member, w_region * r_region, faces)
    gradient[:k] = -(columns.T @ (inverse_shade * pulled))
    if len(member):
        order, pattern = by_region
        entries = (w_region * inverse_shade[member])[order]
        cross = sparse.csr_matrix((entries, pattern.indices, pattern.indptr), shape=pattern.shape) @ columns
        normal[:k, k:] = cross.T
        normal[k:, :k] = cross
        normal[k:, k:] = np.diag(np.bincount(group, w_region, minlength=regions))
        gradient[k:] = -np.bincount(group, w_region * r_region, minlength=regions)
    return normal, gradient


def edge_scale(residuals: np.ndarray) -> np.ndarray:
    """(C,) robust scale per channel of edge residuals (E, C) (:func:`edge_residuals`)."""
    return np.array([robust.robust_scale(np.abs(residuals[:, c])) for c in range(residuals.shape[1])])


def edge_cost(residuals: np.ndarray, scale: np.ndarray) -> float:
    """Cauchy-shaped cost sum log(1 + (r / s)^2) of edge residuals (E, 3) at fixed per-channel
    scales (3,): the sun's cost, with the scales of the sunless fit, so two lights compare."""
    return float(np.sum(np.log1p((residuals / scale) ** 2)))


def edge_cost_ratio(base: np.ndarray, trial: np.ndarray) -> float:
    """The robust cost (:func:`edge_cost`) of ``trial`` edge residuals over that of ``base``
    (both (E, 3)), each channel's scale taken from ``base``; edges that are non-finite in
    either (an unlit face) are left out. Below 1: the trial light explains the edges better."""
    finite = np.all(np.isfinite(base), axis=1) & np.all(np.isfinite(trial), axis=1)
    scale = edge_scale(base[finite])
    return edge_cost(trial[finite], scale) / max(edge_cost(base[finite], scale), 1e-300)
