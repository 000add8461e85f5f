"""All the numbers of a report: one estimate against one synthetic dataset's ground truth."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimator import Estimate, TriangleMesh, sh

from . import metrics, protocols
from .ground_truth import (
    GroundTruth,
    evaluation_mask,
    filtered_illumination,
    sun_direction,
    true_irradiance,
)

SCHEMA = "pseudolight-metrics"
SCHEMA_VERSION = 1


@dataclass
class ImageSet:
    """Predicted and reference images of some cameras (a novel-view, relighting or cross-check set).

    predictions, references : lists of (H, W, 3) linear images; masks : lists of (H, W) bool
    pixels to compare (object pixels); names : one per image. ``align``: scale the
    predictions per channel onto the references first (False for the cross-check,
    where the absolute scale must agree). ``noise``: per image, the predictions' own relative
    Monte Carlo noise (a render's), or None. ``protocols``: the published benchmarks' metric
    sets to add (:mod:`reports.protocols`), under ``"protocols"``.
    """

    names: list[str]
    predictions: list[np.ndarray]
    references: list[np.ndarray]
    masks: list[np.ndarray]
    align: bool = True
    note: str = ""
    noise: list[float] | None = None
    protocols: tuple[str, ...] = ()

    def metrics(self) -> dict:
        per_view = [metrics.image_metrics(p, r, m, self.align)
                    for p, r, m in zip(self.predictions, self.references, self.masks)]
        keys = per_view[0].keys() if per_view else []
        out = {k: float(np.mean([v[k] for v in per_view])) for k in keys}
        out["views"] = len(per_view)
        out["per_view"] = [{"name": n, **v} for n, v in zip(self.names, per_view)]
        for view, noise in zip(out["per_view"], self.noise or []):
            # the render's noise adds in quadrature to the disagreement of the two models
            view["render_noise"] = noise
            view["relative_l2_noise_free"] = float(np.sqrt(max(view["relative_l2"] ** 2 - noise ** 2, 0.0)))
        if self.noise is not None and per_view:
            out["relative_l2_noise_free"] = float(np.mean([v["relative_l2_noise_free"] for v in out["per_view"]]))
        if self.protocols and per_view:
            out["protocols"] = protocols.score(self.names, self.predictions, self.references, self.masks,
                                               self.protocols)
        if self.note:
            out["note"] = self.note
        return out


@dataclass
class Evaluation:
    """The metrics dict plus the arrays the figures need."""

    metrics: dict
    ratios: dict = field(default_factory=dict)          # 'specular'/'diffuse' -> (n, 4) DC-gauge ratios
    filtered_truth_sh: np.ndarray | None = None


def illumination_metrics(est: Estimate, truth: GroundTruth, truth_sh: np.ndarray) -> dict:
    """Errors of the light beyond the SH L2: the irradiance it gives a matte surface, its
    lat-long map's PSNR (both after one scale per channel) and, where the truth has a sun,
    the angle to the estimated light's brightest direction."""
    order = min(metrics.IRRADIANCE_ORDER, est.sh_order)
    if est.radiance_sh is not None:
        radiance = est.radiance_sh
    else:   # the pseudo light is the radiance filtered by the Phong lobe: undo it on degrees 0-2
        lobe = sh.expand_per_degree(sh.phong_filter(order, est.config.phong_exponent))[:, None]
        radiance = est.pseudo_sh[: sh.num_coeffs(order)] / lobe
    sun = sun_direction(truth)
    return {"irradiance_relative_l2": metrics.irradiance_error(radiance, truth.radiance_sh),
            "latlong_psnr": metrics.latlong_psnr(est.pseudo_sh, truth_sh),
            "sun_direction_error_deg": None if sun is None else metrics.direction_error_deg(est.pseudo_sh, sun)}


def evaluate(mesh: TriangleMesh, truth: GroundTruth, est: Estimate, novel: ImageSet | None = None,
             relit: ImageSet | None = None, cross_check: ImageSet | None = None,
             cross_check_tolerance: float = 0.01, shadow: tuple | None = None) -> Evaluation:
    """Compare an estimate with ground truth the way the paper and today's benchmarks do.

    Albedos are compared per face as ratios estimated / true after one global
    scale, in three ways (see :func:`reports.metrics.albedo_ratios`): 'dc' (the
    paper's unit-DC normalisation, nothing fitted), 'lstsq' (per-channel
    least-squares scale, as Stanford-ORB) and 'robust' (least squares on the faces
    that are not gross errors: a few absurd faces cannot move it; the share it set
    aside is reported), on the faces of
    :func:`reports.ground_truth.evaluation_mask`. ``shadow`` = (sampling, visibility):
    a shadow function of the mesh already computed (e.g. the predictor's), reused
    for the true irradiance.
    """
    truth_sh = filtered_illumination(truth, est.sh_order)
    dc = truth.radiance_sh[0]  # DC of the true radiance per channel (the Phong filter is 1 at l = 0)
    out: dict = {"schema": SCHEMA, "schema_version": SCHEMA_VERSION}
    out["illumination"] = {**metrics.sh_comparison(est.pseudo_sh, truth_sh),
                           **illumination_metrics(est, truth, truth_sh)}
    out["faces"] = {"total": int(mesh.num_faces), "estimated": int(est.observed.sum())}
    ratios, albedo = {}, {}
    irradiance = None
    for component in ("specular", "diffuse"):
        true_albedo = getattr(truth, component)
        est_albedo = getattr(est, component)
        if np.all(true_albedo == 0):
            albedo[component] = {"present": False}
            continue
        if irradiance is None:  # shadow function of the truth: computed once, for both components
            irradiance = true_irradiance(mesh, truth, *(shadow or (None, None)))
        mask = evaluation_mask(truth, irradiance, est.observed, component)
        entry = {"present": True, "evaluated_faces": int(mask.sum())}
        for scale in metrics.SCALES:
            r = metrics.albedo_ratios(est_albedo, true_albedo, mask, scale, dc)
            entry[scale] = {"luminance": metrics.ratio_summary(r[:, 3]),
                            "median_ratio_rgb": [metrics.ratio_summary(r[:, c])["median_ratio"] for c in range(3)]}
            if scale == "dc":
                ratios[component] = r
        s = metrics.lstsq_scale(est_albedo[mask], true_albedo[mask])
        de = metrics.ciede2000(est_albedo[mask] * s, true_albedo[mask]) if mask.any() else np.zeros(0)
        entry["psnr_lstsq"] = metrics.albedo_psnr(est_albedo, true_albedo, mask)
        entry["psnr_robust"] = metrics.albedo_psnr(est_albedo, true_albedo, mask, "robust")
        if mask.any():   # the share of faces the robust gauge set aside
            _, aside = metrics.robust_scale(est_albedo[mask], true_albedo[mask])
            entry["robust"]["set_aside_share"] = float(aside.mean())
        history = est.face_stats.get("albedo_history") if component == "diffuse" else None
        seconds = (est.info.get("ad_history") or {}).get("snapshot_seconds")
        if history is not None and seconds is not None and len(seconds) == history.shape[1]:
            # an iterative method's albedo snapshots: its error against time (the peer comparison)
            entry["psnr_history"] = {"seconds": [float(t) for t in seconds],
                                     "psnr_lstsq": [metrics.albedo_psnr(history[:, k], true_albedo, mask)
                                                    for k in range(history.shape[1])]}
        entry["ciede2000"] = {"mean": float(de.mean()) if de.size else None,
                              "median": float(np.median(de)) if de.size else None,
                              "p90": float(np.percentile(de, 90)) if de.size else None}
        albedo[component] = entry
    out["albedo"] = albedo
    if truth.regions is not None:
        o = est.observed & (est.labels >= 0)
        out["clusters"] = {"ari": metrics.adjusted_rand_index(truth.regions[o], est.labels[o]) if o.any() else None,
                           "clusters": int(len(np.unique(est.labels[o]))),
                           "true_regions": int(len(np.unique(truth.regions)))}
    else:
        out["clusters"] = {"ari": None, "clusters": int(len(np.unique(est.labels[est.labels >= 0]))),
                           "true_regions": None}
    for key, images in (("novel_views", novel), ("relighting", relit)):
        out[key] = images.metrics() if images is not None and images.names else None
    if cross_check is not None and cross_check.names:
        cc = cross_check.metrics()
        cc["tolerance"] = cross_check_tolerance
        key = "relative_l2_noise_free" if cross_check.noise is not None else "relative_l2"
        cc["compared"] = key
        cc["pass"] = bool(max(v[key] for v in cc["per_view"]) <= cross_check_tolerance)
        out["mitsuba_cross_check"] = cc
    else:
        out["mitsuba_cross_check"] = None if cross_check is None else {"note": cross_check.note}
    return Evaluation(out, ratios, truth_sh)
