"""Ground truth of a synthetic dataset, and the truth brought into the estimate's terms:
filtered illumination, irradiance and which faces count."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator import (
    EstimatorConfig,
    InputError,
    RayCaster,
    SphereSampling,
    TriangleMesh,
    Visibility,
    compute_visibility,
    diffuse_matrix,
    sh,
    sphere_sampling,
)

from .metrics import LUMINANCE


@dataclass(frozen=True)
class GroundTruth:
    """Exactly known truth of a synthetic dataset.

    Attributes
    ----------
    diffuse, specular : (F, 3) linear per-face albedo (area average over each face).
    radiance_sh : (M, 3) SH of the true radiance illumination (not filtered).
    brdf : dict, e.g. {'model': 'phong', 'exponent': 10.0}.
    illumination : dict describing the light (lights list, or environment map).
    regions : (F,) int region of each face, or None.
    """

    diffuse: np.ndarray
    specular: np.ndarray
    radiance_sh: np.ndarray
    brdf: dict
    illumination: dict
    regions: np.ndarray | None = None

    @property
    def sh_order(self) -> int:
        return sh.order_of(self.radiance_sh.shape[0])

    def known_light(self) -> dict:
        """Keyword arguments of the known-illumination oracle: ``known_sh`` (the true pseudo
        illumination) and ``known_radiance`` (the true radiance SH, unit DC)."""
        r = self.radiance_sh
        return {"known_sh": sh.pseudo_illumination(r, self.brdf["exponent"]),
                "known_radiance": r / np.where(np.abs(r[0]) > 0, r[0], 1.0)}


def filtered_illumination(truth: GroundTruth, order: int) -> np.ndarray:
    """The true pseudo illumination: radiance SH x Phong filter (Ramamoorthi & Hanrahan),
    order ``order``, unit DC per channel -- the estimate's gauge. Shape ((order+1)^2, 3)."""
    return sh.pseudo_illumination(truth.radiance_sh, truth.brdf["exponent"], order)


SUN_SHARE = 0.5   # a directional light is "the sun" when it holds at least this share of the light


def sun_direction(truth: GroundTruth) -> np.ndarray | None:
    """(3,) unit direction towards the true light's sun: the sun of a ``sunsky`` light, or the
    directional light holding at least :data:`SUN_SHARE` of the total luminance; None else."""
    light = truth.illumination or {}
    if light.get("kind") == "sunsky" and isinstance(light.get("sunsky"), dict):
        rotation = np.asarray(light.get("rotation", np.eye(3)), float)
        direction = rotation @ np.asarray(light["sunsky"]["to_sun"], float)
    elif light.get("kind") == "directional" and light.get("lights"):
        to_light = np.array([x["to_light"] for x in light["lights"]], float)
        power = np.array([x["irradiance"] for x in light["lights"]], float) @ [0.2126, 0.7152, 0.0722]
        if power.max() < SUN_SHARE * power.sum():
            return None
        direction = to_light[int(np.argmax(power))]
    else:
        return None
    return direction / np.linalg.norm(direction)


def true_irradiance(mesh: TriangleMesh, truth: GroundTruth, sampling: SphereSampling | None = None,
                    visibility: Visibility | None = None, order: int | None = None) -> np.ndarray:
    """(F, 3) direct irradiance / pi reaching each face centroid from the true light
    (its SH to ``order``, default the estimator's), with self-shadowing: sum_lm L_lm C_lm.

    ``sampling`` and ``visibility`` (the shadow function) are computed with the
    estimator's defaults unless given (a report passes the predictor's own).
    """
    defaults = EstimatorConfig()
    order = defaults.sh_order if order is None else order
    if sampling is None or visibility is None:
        sampling = sphere_sampling(defaults.directions)
        visibility = compute_visibility(RayCaster(mesh), sampling)
    c = diffuse_matrix(mesh, sampling, visibility, order)
    return c @ truth.radiance_sh[: sh.num_coeffs(order)]


def evaluation_mask(truth: GroundTruth, irradiance: np.ndarray, observed: np.ndarray, component: str,
                    min_albedo: float = 0.02, min_light: float = 0.05) -> np.ndarray:
    """Faces where an albedo can be judged.

    A face counts when the estimate observed it, its true albedo (luminance) of
    ``component`` is above ``min_albedo`` x the 99th percentile (non-negligible),
    and it receives light: true irradiance above ``min_light`` x the 95th
    percentile (faces unlit in every view carry no information); ``irradiance`` (F, 3) is
    :func:`true_irradiance`.
    """
    if component not in ("diffuse", "specular"):
        raise InputError(f"component must be 'diffuse' or 'specular', got {component!r}")
    observed = np.asarray(observed)
    if observed.dtype != bool or observed.shape != (len(truth.diffuse),):
        raise InputError(f"observed must be ({len(truth.diffuse)},) bool, got {observed.shape} {observed.dtype}")
    albedo = (truth.diffuse if component == "diffuse" else truth.specular) @ LUMINANCE
    big = albedo > min_albedo * max(np.percentile(albedo, 99), 1e-300)
    return observed & big & lit_faces(irradiance, min_light)


def lit_faces(irradiance: np.ndarray, min_light: float = 0.05) -> np.ndarray:
    """(F,) bool: the faces whose true irradiance (F, 3) (:func:`true_irradiance`, luminance)
    exceeds ``min_light`` x its 95th percentile over the faces. A face below it (turned to an
    unlit part of the environment, as a sky's underside) is dark in every view, whatever its
    albedo: no estimate can be judged there."""
    light = irradiance @ LUMINANCE
    return light > min_light * max(np.percentile(light, 95), 1e-300)
