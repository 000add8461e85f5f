"""The result of a method: per-face albedos and the light, in ``mesh.ply`` face order."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..core import sh
from ..core.errors import InputError
from .reflection_models import ReflectionModel, reflection_model

if TYPE_CHECKING:   # the config composes every room's section; the result only holds it
    from ..config import EstimatorConfig


@dataclass
class Estimate:
    """The result of a method, per face in ``mesh.ply`` order.

    Attributes
    ----------
    diffuse, specular : (F, 3) linear albedo (0 where not observed).
    pseudo_sh : (M, 3) pseudo illumination h, unit DC per channel.
    labels : (F,) int64 cluster of each face, -1 where not observed.
    observed : (F,) bool faces with an estimate.
    method : registry name; config : the EstimatorConfig used.
    info : timings (s) per stage, solver residuals, counts.
    radiance_sh : (M, 3) radiance L (unit DC) when the reflection model solves for it
        (``specular_model='lobe'``: h = L x Phong filter loses the degrees where the
        filter vanishes); else None.
    face_stats : per-face trust arrays (:func:`estimator.diagnostics.trust.diagnose`): ``observations``
        (F,) kept rows, ``albedo_se`` (F, 3) standard error of the diffuse albedo.
    """

    diffuse: np.ndarray
    specular: np.ndarray
    pseudo_sh: np.ndarray
    labels: np.ndarray
    observed: np.ndarray
    method: str
    config: EstimatorConfig
    info: dict = field(default_factory=dict)
    radiance_sh: np.ndarray | None = None
    face_stats: dict = field(default_factory=dict)

    def __post_init__(self):
        """Refuse arrays that disagree on the faces or are not what each attribute holds: a
        Predictor or a report would otherwise broadcast them, or read 0/1 integers as indices."""
        diffuse, specular = np.shape(self.diffuse), np.shape(self.specular)
        if len(diffuse) != 2 or diffuse[1] != 3 or specular != diffuse:
            raise InputError(f"Estimate: diffuse and specular must be (F, 3) alike, got {diffuse} and {specular}")
        f = diffuse[0]
        for name in ("labels", "observed"):
            value = np.asarray(getattr(self, name))
            if value.shape != (f,):
                raise InputError(f"Estimate: {name} must be ({f},), got {value.shape}")
        if np.asarray(self.observed).dtype != bool:
            raise InputError(f"Estimate: observed must be bool, got {np.asarray(self.observed).dtype}")
        if np.asarray(self.labels).dtype.kind not in "iu":
            raise InputError(f"Estimate: labels must be integers, got {np.asarray(self.labels).dtype}")
        light = np.shape(self.pseudo_sh)
        if len(light) != 2 or light[1] != 3:
            raise InputError(f"Estimate: pseudo_sh must be ((L + 1)^2, 3), got {light}")
        sh.order_of(light[0])   # a count that is no (L + 1)^2 is refused by name
        if self.radiance_sh is not None and np.shape(self.radiance_sh) != light:
            raise InputError(f"Estimate: radiance_sh must be shaped like pseudo_sh {light}, "
                             f"got {np.shape(self.radiance_sh)}")

    @property
    def model(self) -> "ReflectionModel":
        """The reflection model of ``config``."""
        return reflection_model(self.config)

    @property
    def light(self) -> np.ndarray:
        """(M, 3) the light unknown of the model: L for a radiance model, else h."""
        return self.radiance_sh if self.model.light == "radiance" else self.pseudo_sh

    @property
    def sh_order(self) -> int:
        return sh.order_of(self.pseudo_sh.shape[0])
