"""A sun: one distant light too small and too bright for the spherical harmonics.

A clear sky's sun (or a probe's) is a disc of half a degree that carries much of the
irradiance. Truncated to order 10 its hard cast shadows ring and blur over ~20 degrees,
and a shadow function sampled over ~1164 directions (~6 degrees apart) cannot place them:
the edge fit of :mod:`estimator.light.edge_fit` then reads the sun's shadow boundaries as
albedo edges.

Here the sun is a delta light of its own. Its shading column is exact,

    s_f(d) = (1 / pi) max(0, n_f . d) x (share of the face's sample points that see d),

traced with shadow rays (no sampled shadow function), and enters the edge fit as one more
column of the diffuse matrix (whose rows carry the same 1 / pi), so its coefficient is the
sun's irradiance in the SH light's units: E Y_lm(d) is the sun as SH. Its
direction d is found by a pattern search on the robust cost of the edge fit, started at
the brightest direction of the SH light and run at a low order (the sun's shadows, not the
sky's detail, decide it). The sun is kept when the drop it brings to the edges' Cauchy
negative log-likelihood exceeds its Bayesian information criterion's price
(:attr:`Sun.explains`) and it lowers that cost by at least ``sun_min_gain`` (a fraction, 0 by
default: the criterion alone), so a probe with no sun keeps the SH light alone.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..core import sh
from ..core.data import TriangleMesh
from ..core.settings import Section
from ..model.reflection import fresnel_dielectric
from ..rays.raycast import RayCaster
from . import edge_fit

SAMPLE_POINTS = 6       # shadow rays per face for its lit share
SEARCH_STEPS_DEG = (6.0, 3.0, 1.5)
MAX_MOVES = 10          # per ring size: a flat cost (no sun) must not wander
SUN_PARAMETERS = 5      # a direction (2) and an irradiance per channel (3)


@dataclass
class SunConfig(Section):
    """The sun search (:func:`find_sun`).

    Attributes
    ----------
    sun_min_gain : a sun (a delta light with exact cast shadows beside the SH light) is kept
        when it explains the edges (:attr:`Sun.explains`: the drop of their Cauchy negative
        log-likelihood exceeds the Bayesian information criterion's price of the sun's
        unknowns) and lowers the edge fit's robust cost by at least this fraction (0: the
        criterion alone); 1 turns the search off.
    max_suns : at most this many compact sources, each kept on the same criterion
        (:func:`find_suns`; each further search costs about as much as the first). 1 by
        default: on the random family's held-out seeds 1040-1059, 4 lost 1.1 dB of median
        PSNR (27.9 against 29.0 dB) and took 1.3 s more per estimate (median). It found the
        second lamp where two light a matte object (seed 1050: 29.9 -> 40.3 dB) but also took
        a coat's glints under one sun for more suns (seed 1057: 30.6 -> 26.1 dB).
    """

    sun_min_gain: float = 0.0
    max_suns: int = 1

    def check(self):
        return [(0 <= self.sun_min_gain <= 1, "sun_min_gain must lie in [0, 1]"),
                (self.max_suns >= 1, "max_suns must be >= 1")]


@dataclass(frozen=True)
class Sun:
    """A sun found in the data.

    Attributes
    ----------
    direction : (3,) unit world direction towards the sun.
    cost_ratio : robust edge cost with the sun over the cost without it (< 1: it helps).
    evaluations : edge fits the search ran.
    coat_ior : the index of the dielectric coat its light passes (None: a bare surface).
    gain : how much the sun lowers the edge cost, sum log(1 + (r / s)^2) at the sunless fit's
        scales: the drop of the residuals' Cauchy negative log-likelihood.
    penalty : the Bayesian information criterion's price of the sun's :data:`SUN_PARAMETERS`
        unknowns, (k / 2) ln n over the n edge residuals; the sun :attr:`explains` the data
        when ``gain`` exceeds it.
    """

    direction: np.ndarray
    cost_ratio: float
    evaluations: int
    coat_ior: float | None = None
    gain: float = np.inf
    penalty: float = 0.0
    others: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def explains(self) -> bool:
        """Whether the sun lowers the edges' negative log-likelihood by more than its BIC price."""
        return self.gain > self.penalty

    @property
    def directions(self) -> np.ndarray:
        """(S, 3) the sun's direction, then those of the further compact sources found after it."""
        return np.vstack([self.direction[None, :], self.others])


def sun_shading(mesh: TriangleMesh, caster: RayCaster, direction: np.ndarray, coat_ior: float | None = None,
                points: int = SAMPLE_POINTS, offset: float = 1e-4) -> np.ndarray:
    """(F,) diffuse-matrix column of a unit-irradiance delta light from ``direction`` (3,):
    the cosine over pi times the share of ``points`` fixed barycentric sample points per
    face whose shadow ray (started ``offset`` x the bounding-box diagonal along the normal)
    escapes; with ``coat_ior``, times the share 1 - F(n . d) that a dielectric coat of that
    index lets through to the diffuse base (a plastic's coat reflects most of a grazing sun)."""
    return sun_shadings(mesh, caster, np.asarray(direction, float)[None, :], coat_ior, points, offset)[:, 0]


def sun_shadings(mesh: TriangleMesh, caster: RayCaster, directions: np.ndarray, coat_ior: float | None = None,
                 points: int = SAMPLE_POINTS, offset: float = 1e-4) -> np.ndarray:
    """(F, R) :func:`sun_shading` columns of R directions (R, 3), their shadow rays traced in
    one batch (the pattern search's ring of candidates: one ray query instead of six)."""
    d = directions / np.linalg.norm(directions, axis=1, keepdims=True)                     # (R, 3)
    normals = mesh.face_normals
    cosine = np.maximum(normals @ d.T, 0.0)                                                 # (F, R)
    face, which = np.nonzero(cosine > 0)                # faces turned away need no shadow ray
    bary = np.random.default_rng(0).dirichlet(np.ones(3), points)                           # (P, 3)
    starts = np.einsum("pk,fkj->fpj", bary, mesh.vertices[mesh.faces[face]])               # (n, P, 3)
    origins = (starts + offset * caster.scale * normals[face, None, :]).reshape(-1, 3)
    rays = np.repeat(d[which], points, axis=0)
    lit = np.zeros(cosine.shape)
    lit[face, which] = caster.escapes(origins, rays).reshape(-1, points).mean(axis=1)
    through = 1.0 if coat_ior is None else 1.0 - fresnel_dielectric(cosine, coat_ior)
    return cosine * through * lit / np.pi


def brightest_direction(light: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(3,) the direction among ``directions`` (K, 3) where the SH light (M, 3) has the
    largest mean over channels."""
    order = sh.order_of(light.shape[0])
    return directions[int(np.argmax((sh.basis(order, directions) @ light).mean(axis=1)))]


def find_sun(radiance: np.ndarray, c_matrix: np.ndarray, edges: np.ndarray, usable: np.ndarray,
             mesh: TriangleMesh, caster: RayCaster, directions: np.ndarray, start: np.ndarray | None = None,
             order: int = 2, start_order: int = 4, steps_deg: tuple[float, ...] = SEARCH_STEPS_DEG,
             iterations: int = 5, loss: str = "cauchy", coat_ior: float | None = None,
             fixed: np.ndarray | None = None) -> Sun:
    """The sun direction that best explains the log radiance ratios of neighbouring faces.

    Parameters
    ----------
    radiance, c_matrix, edges, usable : as in :func:`estimator.light.edge_fit.log_shading_fit`
        (c_matrix (F, M) holds at least ``(order + 1)^2`` SH columns).
    directions : (K, 3) candidate start directions.
    start : (3,) first guess; None: the brightest of ``directions`` under the edge fit's
        light at ``start_order`` (a low-order light places its peak within a few rings of the sun).
    order : SH order of the sky during the search.
    steps_deg : angular steps of the pattern search (six neighbours on a ring), coarse to fine.
    iterations : Gauss-Newton steps of each edge fit (8 gave the same directions, 50 % slower).
    coat_ior : also try the sun's light through a dielectric coat of this index
        (:func:`sun_shading`): after the search with the bare column, the coated one is
        tried there and, when it costs less, kept and refined at the finest step. (Choosing
        the column before the search lets the coat's column steer a bare surface's search to
        a wrong optimum: the bare column places the shadows, which decide the direction.)
    fixed : (F, S) exact columns of suns already found (:func:`find_suns`), fitted beside the
        sky in every trial and in the fit without this sun; None: none.

    Returns
    -------
    Sun, with the cost ratio against the same fit without a sun: sum log(1 + (r / s)^2)
    over the edge residuals r, with each channel's robust scale s fixed by the sunless fit;
    the cost's drop (``gain``) and its BIC ``penalty``. A trial whose fitted sun irradiance
    is not positive in every channel costs infinity.
    """
    fixed = np.zeros((len(c_matrix), 0)) if fixed is None else fixed
    low = np.hstack([c_matrix[:, :sh.num_coeffs(order)], fixed])
    fit = dict(loss=loss, iterations=iterations)
    if start is None:
        width = min(sh.num_coeffs(start_order), c_matrix.shape[1])
        coarse = np.hstack([c_matrix[:, :width], fixed])
        start = brightest_direction(edge_fit.log_shading_fit(radiance, coarse, edges, usable, loss=loss)[0][:width],
                                    directions)
    base_light, _ = edge_fit.log_shading_fit(radiance, low, edges, usable, **fit)
    base = edge_fit.edge_residuals(radiance, low @ base_light, edges, usable)
    scale = edge_fit.edge_scale(base)

    def cost(d, ior):
        return cost_of_column(sun_shading(mesh, caster, d, ior))

    def cost_of_column(column):
        columns = np.hstack([low, column[:, None]])
        light, _ = edge_fit.log_shading_fit(radiance, columns, edges, usable, **fit)
        if np.any(light[-1 - fixed.shape[1]:] <= 0):   # a sun takes light away nowhere: a dark albedo patch is no sun
            return np.inf
        return edge_fit.edge_cost(edge_fit.edge_residuals(radiance, columns @ light, edges, usable), scale)

    base_cost = edge_fit.edge_cost(base, scale)

    def descend(d, best, ior, steps):
        """Pattern search from ``d``: move to the best of six neighbours on a ring while it
        lowers the cost, then shrink the ring. Returns (direction, cost, evaluations)."""
        evaluations = 0
        for step in np.radians(steps):
            moved, moves = True, 0
            while moved and moves < MAX_MOVES:
                moves += 1
                u, v = _tangent_frame(d)
                ring = [np.cos(step) * d + np.sin(step) * (np.cos(a) * u + np.sin(a) * v)
                        for a in np.arange(6) * np.pi / 3]
                shadings = sun_shadings(mesh, caster, np.array(ring), ior)
                costs = [cost_of_column(shadings[:, k]) for k in range(len(ring))]
                evaluations += len(ring)
                k = int(np.argmin(costs))
                moved = costs[k] < best
                if moved:
                    best, d = costs[k], ring[k] / np.linalg.norm(ring[k])
        return d, best, evaluations

    d = np.asarray(start, float) / np.linalg.norm(start)
    d, best, evaluations = descend(d, cost(d, None), None, steps_deg)
    ior, evaluations = None, evaluations + 1
    if coat_ior is not None:   # the bare sun places the shadows; then the coat's column, refined at the finest step
        coated = cost(d, coat_ior)
        evaluations += 1
        if coated < best:
            d, best, more = descend(d, coated, coat_ior, steps_deg[-1:])
            ior, evaluations = coat_ior, evaluations + more
    residuals = int(np.isfinite(base).all(axis=1).sum()) * base.shape[1]
    return Sun(d, best / max(base_cost, 1e-300), evaluations, ior, gain=base_cost - best,
               penalty=0.5 * SUN_PARAMETERS * np.log(max(residuals, 2)))


def find_suns(radiance: np.ndarray, c_matrix: np.ndarray, edges: np.ndarray, usable: np.ndarray,
              mesh: TriangleMesh, caster: RayCaster, directions: np.ndarray, loss: str = "cauchy",
              coat_ior: float | None = None, max_suns: int = 1) -> Sun:
    """:func:`find_sun`, then while the sun explains the edges (:attr:`Sun.explains`), up to
    ``max_suns`` in all, a further compact source searched with the ones found fitted beside
    the sky (a room's lamps, several small emitters: each casts hard shadows that the SH light
    rings about) and kept on the same criterion, its Bayesian information criterion's price
    included; its column passes the same coat as the first's. The first sun's ``cost_ratio``,
    ``gain`` and ``penalty`` decide whether the sun is used (:func:`find_sun`); the others sit
    in :attr:`Sun.others`."""
    first = find_sun(radiance, c_matrix, edges, usable, mesh, caster, directions, loss=loss, coat_ior=coat_ior)
    if not first.explains:
        return first
    found, evaluations = [first.direction], first.evaluations
    columns = sun_shadings(mesh, caster, first.direction[None, :], first.coat_ior)
    while len(found) < max_suns:
        more = find_sun(radiance, c_matrix, edges, usable, mesh, caster, directions, loss=loss, fixed=columns)
        evaluations += more.evaluations
        if not more.explains:
            break
        found.append(more.direction)
        columns = np.hstack([columns, sun_shadings(mesh, caster, more.direction[None, :], first.coat_ior)])
    return replace(first, evaluations=evaluations, others=np.array(found[1:]).reshape(-1, 3))


def _tangent_frame(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors orthogonal to ``d`` (3,) and to each other."""
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(d, a)
    u /= np.linalg.norm(u)
    return u, np.cross(d, u)

