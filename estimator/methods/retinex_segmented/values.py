"""The values the stages of ``retinex-segmented`` pass on: where the light came from, the
shading (with its sun), one light hypothesis, and the solve's context."""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import sparse

from ...core import sh
from ...light import coat
from ...light.coat_map import ReflectedLight
from ...light.lobe_light import LobeLight
from ...light.sun import Sun
from ...model.estimate import Estimate
from ...model.reflection_models import ReflectionModel
from ...pipeline.observations import Observations
from ...pipeline.prepared import Prepared

if TYPE_CHECKING:   # the config composes every room's section, this one's too
    from ...config import EstimatorConfig


class LightSource(str, Enum):
    """Where the light came from; the value is the run's ``info['light_from']``."""

    EDGES = "edges"
    EDGES_AND_REGIONS = "edges and regions"
    EDGES_AND_PARTED_REGIONS = "edges and parted regions"
    EDGES_AND_KEPT_REGIONS = "edges and the first fit's regions"
    COAT_MAP = "reflection"
    COAT_MAP_AND_REGIONS = "reflection and regions"
    COAT_MAP_DIFFUSE = "reflection's diffuse, edges' light"
    LOBE = "reflection (lobe)"
    LOBE_AND_REGIONS = "reflection (lobe) and regions"

    @property
    def models_the_coat(self) -> bool:
        """True when the light came from a reflection fit, which already holds the coat."""
        return self.value.startswith("reflection")

    @property
    def from_coat_map(self) -> bool:
        """True when the light and the faces' diffuse radiance came from the coat's map."""
        return self.models_the_coat and "lobe" not in self.value


@dataclass(frozen=True)
class Shading:
    """Each face's shading columns: (F, M) for the SH light, then one column per source of the
    sun when ``sun`` is set (:attr:`Sun.directions`; their irradiances are the light's last rows).
    ``coat_ior``: the SH columns hold the light that passes a smooth coat of that index on its way
    in (None: the model's diffuse rows)."""

    columns: np.ndarray
    sun: Sun | None = None
    coat_ior: float | None = None

    def with_sun(self, sun: Sun, column: np.ndarray) -> "Shading":
        """(F, M + S): these columns and the sun's (F,) column, or its S sources' (F, S)."""
        return Shading(np.hstack([self.columns, column.reshape(len(column), -1)]), sun, self.coat_ior)


@dataclass
class Hypothesis:
    """One way the light may be: the light with its shading, and what follows under it.

    Attributes
    ----------
    radiance : (F, 3) each face's diffuse radiance the light was fitted to.
    light : (M', 3) the light unknown (the sun's irradiances last when ``shading.sun``).
    shading : the columns the light multiplies.
    albedo : (F, 3) radiance over the shading (a region's faces share its albedo).
    lit : (F,) faces whose albedo is determined.
    labels : (F,) uniform region of each face, -1 outside every region.
    regions : number of uniform regions (0: a texture).
    share : share of the lit faces that the segmentation put in uniform regions.
    source : where the light came from.
    found : the sun the search found (reported even when unused), or None.
    deviation, drift : the regions' deviation and drift (None: not measured).
    """

    radiance: np.ndarray
    light: np.ndarray
    shading: Shading
    albedo: np.ndarray
    lit: np.ndarray
    labels: np.ndarray
    regions: int
    share: float
    source: LightSource
    found: Sun | None
    deviation: float | None = None
    drift: float | None = None


@dataclass
class ReflectionFits:
    """The view-dependent fits of one solve, made on first need from the observations before any
    coat correction: the coat's map and the lobe's light with the lobe rows of every observation;
    and the interreflection's operator (:func:`estimator.light.indirect.indirect_transfer`),
    which the fit and each coat refit apply to their own radiance."""

    observations: Observations
    coat_map: ReflectedLight | None = None
    lobe: tuple[LobeLight, np.ndarray] | None = None
    transfer: sparse.csr_matrix | None = None


@dataclass
class FitContext:
    """What every stage of one fit reads: the prepared problem, the settings, and per-face facts
    of the fit (the mesh's edges, the usable faces, the edge fit's keyword arguments)."""

    prep: Prepared
    config: "EstimatorConfig"
    model: ReflectionModel
    loss: str
    fits: ReflectionFits
    edges: np.ndarray
    usable: np.ndarray
    fit: dict[str, Any] = field(default_factory=dict)
    extra: Any = 0.0   # (F, 3) indirect shading, or 0.0
    # the colours as recorded (False: less a coat's reflection or level a refit subtracted,
    # whose misfit differs from face to face)
    recorded: bool = True

    @property
    def plain_fit(self) -> dict[str, Any]:
        """The edge fit's keyword arguments without the indirect shading (a fit of ratios between
        columns, whose scale the indirect term must not set)."""
        return {k: v for k, v in self.fit.items() if k != "indirect"}

    @property
    def sky_width(self) -> int:
        """M: the SH light's columns (without a sun)."""
        return sh.num_coeffs(self.model.order)


@dataclass(frozen=True)
class CoatReflection:
    """The coat's reflection a solve subtracted from the colours: observation k of a face in
    coat group g loses ``weight[g] * rows(...)[k]``.

    Attributes
    ----------
    light : (M, 3) the light whose low orders the coat reflects (the first fit's).
    weight : (G, 3) the coat's colour per coat group (:func:`.method.coat_groups`; one group
        unless ``coat_per_region``).
    order : the light's SH degree the reflection carries (0: the environment's mean level).
    exponent : None for a dielectric coat; else the reflection is a Phong lobe's of this
        exponent (:func:`estimator.light.coat.lobe_rows`: no Fresnel factor, the whole light
        filtered by the lobe, where the mirror direction escapes the object).
    """

    light: np.ndarray
    weight: np.ndarray
    order: int
    exponent: float | None = None

    def rows(self, normals: np.ndarray, view_dir: np.ndarray, ior: float, escapes: np.ndarray) -> np.ndarray:
        """(N, 3) the reflection per unit weight (:func:`estimator.light.coat.coat_rows`) of
        observations with face normals (N, 3) and directions to the camera (N, 3).

        The mirror direction's escape from the object ``escapes`` (N,) applies to the
        environment's mean level alone: a level the same in every direction varies over the
        surface only where the object blocks it. The low orders' rows stay without it (with it,
        three coated seeds of the random family's development set lost 0.2-1.1 dB and one
        gained 0.2)."""
        if self.exponent is not None:
            return coat.lobe_rows(normals, view_dir, self.light, [self.exponent], escapes)[0]
        return coat.coat_rows(normals, view_dir, self.light, self.order, ior, escapes if self.order == 0 else None)

    def unregioned(self, face: np.ndarray, view_dir: np.ndarray, prep: Prepared, ior: float) -> np.ndarray:
        """(N, 3) the reflection subtracted from observations of faces ``face`` (N,) seen along
        ``view_dir`` (N, 3) that lie in no region of the fit: at the last coat group's weight,
        the one the faces outside every region share (the only one without ``coat_per_region``)."""
        normals = prep.data.mesh.face_normals[face]
        escapes = coat.mirror_escapes(face, normals, view_dir, prep.sampling, prep.visibility)
        return self.weight[-1] * self.rows(normals, view_dir, ior, escapes)


@dataclass
class Solution:
    """What a held solve found: the estimate, the hypothesis it came from, the coat's
    reflection subtracted before its fit (None: none), its view-dependent fits and the coat's
    view-independent level (3,) subtracted from every colour before both (0: none)."""

    estimate: Estimate
    hypothesis: Hypothesis
    coat: CoatReflection | None
    fits: ReflectionFits
    level: np.ndarray = field(default_factory=lambda: np.zeros(3))
