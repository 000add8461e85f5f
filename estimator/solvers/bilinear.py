"""Alternating least squares for the bilinear system of Eq. 17."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import sparse

from ..core.errors import InputError
from ..core.gauge import unit_dc
from ..core.settings import Section

COMPONENTS = ("both", "specular", "diffuse")


@dataclass
class BilinearConfig(Section):
    """The bilinear solve (:func:`solve_bilinear`).

    Attributes
    ----------
    iterations, tol : cap on the Levenberg-Marquardt steps and their relative cost-change stop
        (the alternating least squares before them take a fixed five steps).
    components : 'both', 'specular' (t_d = 0, the earth experiment) or 'diffuse'.
    lm_damping_start, lm_damping_raise, lm_damping_lower, lm_damping_max : the
        Levenberg-Marquardt schedule: initial damping, factor on a rejected step, divisor
        after an accepted one, and the damping at which a step is given up (Madsen, Nielsen
        & Tingleff's usual values; raising by more than lowering keeps the solver from
        oscillating between the two).
    """

    iterations: int = 20
    tol: float = 1e-6
    components: str = "both"
    lm_damping_start: float = 1e-3
    lm_damping_raise: float = 4.0
    lm_damping_lower: float = 3.0
    lm_damping_max: float = 1e8

    def check(self):
        return [
            (self.iterations >= 1, "iterations must be >= 1"),
            (self.tol >= 0, "tol must be >= 0"),
            (self.components in COMPONENTS, f"components must be one of {COMPONENTS}"),
            (self.lm_damping_start > 0 and self.lm_damping_max > self.lm_damping_start,
             "lm_damping_start must be > 0 and below lm_damping_max"),
            (self.lm_damping_raise > 1 and self.lm_damping_lower > 1,
             "lm_damping_raise and lm_damping_lower must be > 1"),
        ]

    @property
    def lm_schedule(self) -> tuple[float, float, float, float]:
        """(start, raise, lower, max) damping of the Levenberg-Marquardt solve."""
        return self.lm_damping_start, self.lm_damping_raise, self.lm_damping_lower, self.lm_damping_max


LM_SCHEDULE = BilinearConfig().lm_schedule


@dataclass
class BilinearResult:
    """Solution of the bilinear system.

    Attributes
    ----------
    diffuse, specular : (G, 3) albedo of each group.
    light : (M, 3) the light unknown of the reflection model (pseudo illumination h or
        radiance L), DC coefficient 1 per channel (the scale gauge).
    residuals : relative residual ||R - model|| / ||R|| after each ALS step, then after LM.
    lm_residuals : per channel, the channel's relative residual after each accepted LM step.
    weights : (N,) the observations' weights in the final solve (set by robust callers).
    """

    diffuse: np.ndarray
    specular: np.ndarray
    light: np.ndarray
    residuals: list[float] = field(default_factory=list)
    lm_residuals: list[list[float]] = field(default_factory=list)
    weights: np.ndarray | None = None


def _solve_albedos(r, a, b, group, num_groups, components, ridge=1e-12):
    """Per group: min sum (r - td a - ts b)^2 with td, ts >= 0 (2x2 active set). r, a, b: (N,)."""
    def s(w):
        return np.bincount(group, w, minlength=num_groups)

    saa, sbb, sab, sra, srb = s(a * a), s(b * b), s(a * b), s(r * a), s(r * b)
    td_only = sra / np.maximum(saa, ridge)
    ts_only = srb / np.maximum(sbb, ridge)
    if components == "diffuse":
        return np.maximum(td_only, 0), np.zeros(num_groups)
    if components == "specular":
        return np.zeros(num_groups), np.maximum(ts_only, 0)
    det = saa * sbb - sab * sab
    scale = np.maximum(saa * sbb, ridge)
    ok = det > 1e-10 * scale
    safe = np.where(ok, det, 1.0)
    td = np.where(ok, (sra * sbb - srb * sab) / safe, td_only)
    ts = np.where(ok, (srb * saa - sra * sab) / safe, 0.0)
    # active set: a negative albedo is fixed at 0 and the other re-solved
    neg_d, neg_s = td < 0, ts < 0
    td, ts = np.where(neg_d, 0.0, td), np.where(neg_d, ts_only, ts)
    td, ts = np.where(neg_s & ~neg_d, td_only, td), np.where(neg_s & ~neg_d, 0.0, ts)
    return np.maximum(td, 0), np.maximum(ts, 0)


def _component_rows(components: str, c_rows: np.ndarray, d_rows: np.ndarray) -> list[np.ndarray]:
    """The (N, M) rows each unknown albedo of a group multiplies, in the albedos' order."""
    return {"both": [c_rows, d_rows], "specular": [d_rows], "diffuse": [c_rows]}[components]


def _light_step(r: np.ndarray, group: np.ndarray, albedos: list[np.ndarray], component_rows: list[np.ndarray],
                ridge: float) -> np.ndarray:
    """(M,) one channel's light with the albedos fixed: least squares of r (N,) on the rows
    sum_p albedos[p][group] component_rows[p] (each (G,) and (N, M)), with a Tikhonov weight
    ``ridge`` relative to the mean diagonal."""
    rows = albedos[0][group, None] * component_rows[0]
    for a, x in zip(albedos[1:], component_rows[1:]):
        rows += a[group, None] * x
    gram = rows.T @ rows
    m = gram.shape[0]
    gram[np.diag_indices(m)] += ridge * np.trace(gram) / m
    return np.linalg.solve(gram, rows.T @ r)


@dataclass
class _GroupedRows:
    """The Levenberg-Marquardt steps' normal matrix is formed from these, shared by the channels.

    It is formed in float32 (half the time of float64), while the gradient and the cost stay
    in float64: an approximate Hessian changes the path of the steps, not the point where the
    exact gradient vanishes, and a step is kept only when the exact cost falls.

    Attributes
    ----------
    order : (N,) the observations sorted by group (stable).
    group : (N,) their groups in that order.
    rows : per unknown albedo, its (N, M) rows in that order, float32.
    members : (G, N) sparse sums over each group's sorted rows; its ``data`` is refilled per step.
    """

    order: np.ndarray
    group: np.ndarray
    rows: list[np.ndarray]
    members: sparse.csr_matrix

    @classmethod
    def build(cls, group: np.ndarray, num_groups: int, rows: list[np.ndarray]) -> "_GroupedRows":
        order = np.argsort(group, kind="stable")
        starts = np.r_[0, np.cumsum(np.bincount(group, minlength=num_groups))]
        members = sparse.csr_matrix((np.ones(len(group), dtype=np.float32), np.arange(len(group)), starts),
                                    shape=(num_groups, len(group)))
        return cls(order, group[order], [x[order].astype(np.float32) for x in rows], members)


def _lm_channel(r, group, num_groups, c_rows, d_rows, alb, h, components, iterations, tol, residuals, norm,
                schedule, grouped: _GroupedRows):
    """Levenberg-Marquardt on one channel, albedos eliminated by their Schur complement.

    alb : (G, P) albedos of the unknown components; h : (M,) light. ``schedule``: (start,
    raise, lower, max) damping. ``grouped``: the rows' float32 layout, shared by the channels.
    Returns refined (alb, h).
    """
    lam, lam_raise, lam_lower, lam_max = schedule
    rows = _component_rows(components, c_rows, d_rows)
    order, sorted_group, rows32, members = grouped.order, grouped.group, grouped.rows, grouped.members
    # the (N, M) Jacobian (sorted by group) is refilled in place every step: a fresh array of
    # this size costs more in page faults than the arithmetic that fills it
    jac = np.empty(c_rows.shape, dtype=np.float32)
    scratch = np.empty(c_rows.shape, dtype=np.float32) if len(rows) > 1 else None

    def model(alb_, h_):
        feats = np.stack([x @ h_ for x in rows], 1)                           # (N, P)
        return feats, np.sum(alb_[group] * feats, axis=1)

    feats, pred = model(alb, h)
    cost = float(np.sum((r - pred) ** 2))
    m, p = len(h), alb.shape[1]
    for _ in range(iterations):
        e = r - pred
        scale = alb.astype(np.float32)[sorted_group]                            # (N, P), sorted
        np.multiply(rows32[0], scale[:, 0, None], out=jac)                      # d pred / d h, sorted
        for i in range(1, p):
            jac += np.multiply(rows32[i], scale[:, i, None], out=scratch)
        u = np.stack([np.stack([np.bincount(group, feats[:, i] * feats[:, j], minlength=num_groups)
                                for j in range(p)], -1) for i in range(p)], -2)  # (G, P, P)
        g_alb = np.stack([np.bincount(group, feats[:, i] * e, minlength=num_groups) for i in range(p)], -1)
        # w[g, q] = sum over group g of feats_q jac = sum_i alb[g, i] (sum of feats_q rows_i):
        # sparse products with the fixed rows, not with a scaled copy of the Jacobian
        w = np.zeros((num_groups, p, m))
        for q in range(p):
            members.data = feats[order, q].astype(np.float32)
            for i in range(p):
                w[:, q] += alb[:, i, None] * (members @ rows32[i])
        v = (jac.T @ jac).astype(np.float64)
        g_h = sum(x.T @ (alb[group, i] * e) for i, x in enumerate(rows))   # jac^T e in float64
        while True:
            u_d = u + lam * (u * np.eye(p)) + 1e-12 * np.eye(p)
            v_d = v + lam * np.diag(np.diag(v)) + 1e-12 * np.trace(v) / m * np.eye(m)
            # u_d^-1 = root^T root (root: the inverse Cholesky factor), so the Schur complement's
            # product is a symmetric rank-k update, half the work of a general product
            root = np.linalg.inv(np.linalg.cholesky(u_d))                      # (G, P, P)
            u_inv = np.swapaxes(root, 1, 2) @ root
            half = (root.astype(np.float32) @ w.astype(np.float32)).reshape(-1, m)   # (G P, M)
            schur = v_d - (half.T @ half).astype(np.float64)
            rhs = g_h - w.reshape(-1, m).T @ np.einsum("gpq,gq->gp", u_inv, g_alb).reshape(-1)
            dh = np.linalg.solve(schur, rhs)
            dalb = np.einsum("gpq,gq->gp", u_inv, g_alb - w @ dh)
            alb_new, h_new = np.maximum(alb + dalb, 0.0), h + dh
            feats_new, pred_new = model(alb_new, h_new)
            cost_new = float(np.sum((r - pred_new) ** 2))
            if cost_new < cost or lam > lam_max:
                break
            lam *= lam_raise
        if cost_new >= cost:
            break
        improvement = (cost - cost_new) / max(cost, 1e-300)
        alb, h, feats, pred, cost = alb_new, h_new, feats_new, pred_new, cost_new
        lam = max(lam / lam_lower, 1e-9)
        residuals.append(np.sqrt(cost) / norm)
        if improvement < tol:
            break
    return alb, h


def solve_bilinear(rgb: np.ndarray, group: np.ndarray, c_rows: np.ndarray, d_rows: np.ndarray,
                   num_groups: int, components: str = "both", iterations: int = 20, tol: float = 1e-6,
                   fixed_light: np.ndarray | None = None, ridge: float = 1e-9,
                   als_iterations: int = 5, schedule: tuple[float, float, float, float] = LM_SCHEDULE,
                   initial_light: np.ndarray | None = None) -> BilinearResult:
    """Solve the bilinear system: alternating least squares, then Levenberg-Marquardt.

    The model of observation k (face i in group g, one colour channel) is
    R_k = t_d[g] (C_i . h) + t_s[g] (D_k . h). ALS (albedos of every group with
    the light fixed, then the light with the albedos fixed) gives a start;
    plain ALS converges slowly on this problem, so Levenberg-Marquardt steps
    on all unknowns follow, with the per-group albedos eliminated by their
    Schur complement (an M x M system per step). Albedos stay >= 0. Each
    channel is solved independently; the gauge is unit DC of h per channel.

    Parameters
    ----------
    rgb : (N, 3) observed colours.
    group : (N,) group (cluster) of each observation's face, in [0, G).
    c_rows : (N, M) diffuse matrix row of each observation's face (C_i).
    d_rows : (N, M) mirror matrix rows (D_k).
    components : 'both', 'specular' (t_d = 0) or 'diffuse' (t_s = 0).
    iterations : cap on the Levenberg-Marquardt steps.
    tol : stop when the squared residual improves by less than this fraction.
    fixed_light : (M, 3) known light: only albedos are solved.
    ridge : Tikhonov weight of the ALS light step, relative to the mean diagonal.
    als_iterations : ALS steps before Levenberg-Marquardt.
    schedule : Levenberg-Marquardt damping (start, raise, lower, max).
    initial_light : (M, 3) start of the light (a previous solve's): Levenberg-Marquardt
        starts from it and the albedos fitted to it, without ALS steps.

    Returns
    -------
    BilinearResult with the residual after every step (ALS, then LM).
    """
    if components not in COMPONENTS:
        raise InputError(f"components must be one of {COMPONENTS}, got {components!r}")
    n, m = c_rows.shape
    if rgb.shape != (n, 3) or d_rows.shape != (n, m) or group.shape != (n,):
        raise InputError("solve_bilinear: rgb (N, 3), group (N,), c_rows and d_rows (N, M) must agree")
    h = np.zeros((m, 3))
    h[0] = 1.0
    if fixed_light is not None:
        h = np.array(fixed_light, dtype=np.float64)
    elif initial_light is not None:
        if initial_light.shape != (m, 3):
            raise InputError(f"solve_bilinear: initial_light must be ({m}, 3), got {initial_light.shape}")
        h = np.array(initial_light, dtype=np.float64)
    td, ts = np.zeros((num_groups, 3)), np.zeros((num_groups, 3))
    norm = max(float(np.linalg.norm(rgb)), 1e-300)
    residuals: list[float] = []

    def relative_residual():
        pred = td[group] * (c_rows @ h) + ts[group] * (d_rows @ h)
        return float(np.linalg.norm(rgb - pred) / norm)

    # the unknown albedos (views of td and ts, filled in place) and the rows each multiplies
    albedos = {"both": (td, ts), "specular": (ts,), "diffuse": (td,)}[components]
    component_rows = _component_rows(components, c_rows, d_rows)
    # a given light (fixed, or a previous solve's start) needs only the albedos fitted to it
    light_steps = als_iterations if fixed_light is None and initial_light is None else 0
    for step in range(max(light_steps, 1)):
        for ch in range(3):
            td[:, ch], ts[:, ch] = _solve_albedos(rgb[:, ch], c_rows @ h[:, ch], d_rows @ h[:, ch],
                                                  group, num_groups, components)
        if step < light_steps:
            for ch in range(3):
                h[:, ch] = _light_step(rgb[:, ch], group, [a[:, ch] for a in albedos], component_rows, ridge)
        residuals.append(relative_residual())
    if fixed_light is None and iterations > 0:
        lm_residuals = [[] for _ in range(3)]
        grouped = _GroupedRows.build(group, num_groups, component_rows)
        for ch in range(3):
            alb = {"both": np.stack([td[:, ch], ts[:, ch]], 1), "specular": ts[:, ch, None],
                   "diffuse": td[:, ch, None]}[components]
            alb, h[:, ch] = _lm_channel(rgb[:, ch], group, num_groups, c_rows, d_rows, alb, h[:, ch],
                                        components, iterations, tol, lm_residuals[ch], norm, schedule, grouped)
            if components == "both":
                td[:, ch], ts[:, ch] = alb[:, 0], alb[:, 1]
            elif components == "specular":
                ts[:, ch] = alb[:, 0]
            else:
                td[:, ch] = alb[:, 0]
        # the gauge: unit DC per channel, albedos absorb the scale
        h, dc = unit_dc(h)
        td, ts = td * dc, ts * dc
        residuals.append(relative_residual())
        return BilinearResult(td, ts, h, residuals, lm_residuals)
    return BilinearResult(td, ts, h, residuals)
