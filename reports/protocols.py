"""The image metrics of published inverse-rendering benchmarks, as named protocols.

Each protocol declares how it aligns a prediction with its reference (an estimate's light and
albedo are known only up to a scale per channel) and which numbers it reports, so that a
figure of this harness can be set beside a published one. Every function takes lists of
linear Rec.709 images: predictions and references (H, W, 3) and the pixels to compare (H, W)
bool, one entry per view.

- ``stanford-orb`` (Kuang et al. 2023, the benchmark's ``orb/utils/metrics.py`` and
  ``test.py``): the mask eroded by a 5 x 5 box; per image and channel a least-squares scale;
  PSNR-H on linear values clipped to [0, 4] after both images are brought to the reference's
  mean sRGB level; PSNR-L on sRGB values of the images clipped to [0, 1]; both as the mean
  over the whole image (background zero) and never below the PSNR of a grey 0.5 object; SSIM
  on the sRGB images (Gaussian window of 3 pixels, sigma 1.5, reflected borders, clipped
  to [-1, 1]); LPIPS (VGG) on the sRGB images encoded once more (as that code does), where
  its weights are present.
- ``nerfactor``: per image and channel a least-squares scale, values clipped to [0, 1] and
  encoded with gamma 1/2.2, PSNR and SSIM on the compared pixels.
- ``tensoir``: one scale per channel for the whole set, the median of the reference's ratio
  to the prediction over every compared pixel of every view; sRGB of values clipped to
  [0, 1]; PSNR and SSIM.
- ``raw``: no alignment at all: PSNR of the linear values (peak: the reference's maximum),
  PSNR of the report's tone map, and HDR-ꟻLIP (Andersson et al. 2021, ``flip-evaluator``).

The lower PSNR bound, the erosion and the clipping follow the reference implementation's
code; ``benchmarks/protocol_check.py`` compares these numbers with it.
"""
from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from estimator import psnr_db

from . import metrics

ORB_ERODE = 5            # Stanford-ORB's mask erosion: a 5 x 5 box (pixels)
ORB_HDR_MAX = 4.0        # PSNR-H clips linear values to [0, 4]
ORB_SSIM_WINDOW = 3      # Stanford-ORB calls kornia's SSIM with a 3-pixel window
SSIM_SIGMA = 1.5         # Wang et al. 2004
NERFACTOR_GAMMA = 2.2
_LPIPS = None            # the LPIPS network, built on first use


@dataclass(frozen=True)
class Protocol:
    """A named metric set: ``alignment`` says in words how predictions are scaled, ``score``
    maps (predictions, references, masks) to per-view dicts of numbers (and may add
    set-level keys under ``"set"``); ``higher_is_better`` names each metric's direction."""

    name: str
    alignment: str
    higher_is_better: dict[str, bool]
    score: Callable[[list, list, list], dict]


def _orb_erode(mask: np.ndarray) -> np.ndarray:
    """The mask shrunk by a 5 x 5 box; pixels beyond the image border count as inside (as
    OpenCV's erode does by default)."""
    return ndimage.binary_erosion(mask, structure=np.ones((ORB_ERODE, ORB_ERODE), bool), border_value=1)


def _lstsq_channels(prediction: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(3,) least-squares scale per channel of ``prediction`` onto ``reference`` over ``mask``;
    a channel with no energy in the prediction keeps the reference's mean (its prediction
    stays zero), as the reference implementation does."""
    p, r = prediction[mask], reference[mask]
    energy = (p * p).sum(0)
    return np.where(energy > 1e-6, (p * r).sum(0) / np.maximum(energy, 1e-300), 0.0)


def _orb_psnr(prediction: np.ndarray, reference: np.ndarray, mask: np.ndarray, hdr: bool) -> tuple:
    """Stanford-ORB's PSNR-H (``hdr``) or PSNR-L and the two images it compared (H, W, 3)."""
    m = mask[..., None].astype(np.float64)
    pred, ref = prediction * m, np.maximum(reference * m, 0.0)
    if hdr:   # both to the reference's mean sRGB level: linear images are too dark otherwise
        clipped = np.clip(ref, 0.0, 1.0)
        if clipped.mean() > 1e-8:
            level = metrics.srgb_encode(clipped).mean() / clipped.mean()
            pred, ref = pred * level, ref * level
    pred = pred * _lstsq_channels(pred, ref, mask)
    peak = ORB_HDR_MAX if hdr else 1.0
    pred, ref = np.clip(pred, 0.0, peak), np.clip(ref, 0.0, peak)
    if not hdr:
        pred, ref = metrics.srgb_encode(pred), metrics.srgb_encode(ref)
    mse = float(np.mean((pred - ref) ** 2))
    grey = float(np.mean((0.5 * m - ref) ** 2))   # the score of a grey object: the floor
    return max(psnr_db(mse, 1.0), psnr_db(grey, 1.0)), pred, ref


def ssim_map(a: np.ndarray, b: np.ndarray, window: int, peak: float = 1.0) -> np.ndarray:
    """(H, W, 3) SSIM map of two images with a Gaussian window of ``window`` pixels (sigma
    1.5), borders reflected without repeating the edge pixel, K1 0.01, K2 0.03, as kornia's
    ``ssim`` computes it (the one Stanford-ORB calls). scikit-image's function cannot take
    this window: its Gaussian weights are sized from sigma alone."""
    x = np.arange(window) - window // 2
    kernel = np.exp(-(x ** 2) / (2 * SSIM_SIGMA ** 2))
    kernel /= kernel.sum()

    def blur(img):
        out = ndimage.correlate1d(img, kernel, axis=0, mode="mirror")
        return ndimage.correlate1d(out, kernel, axis=1, mode="mirror")

    c1, c2 = (0.01 * peak) ** 2, (0.03 * peak) ** 2
    mu_a, mu_b = blur(a), blur(b)
    var_a, var_b = blur(a * a) - mu_a ** 2, blur(b * b) - mu_b ** 2
    cov = blur(a * b) - mu_a * mu_b
    return ((2 * mu_a * mu_b + c1) * (2 * cov + c2)) / ((mu_a ** 2 + mu_b ** 2 + c1) * (var_a + var_b + c2) + 1e-12)


def lpips_vgg(prediction_srgb: np.ndarray, reference_srgb: np.ndarray) -> tuple[float | None, str | None]:
    """LPIPS with the VGG backbone of two sRGB images in [0, 1] (H, W, 3), or (None, reason)
    where the optional extra (``pip install .[lpips]``: PyTorch, ``lpips``) or the backbone's
    weights (which torchvision downloads on first use) are missing."""
    reason = lpips_unavailable()
    if reason:
        return None, reason
    import lpips
    import torch

    global _LPIPS
    if _LPIPS is None:
        _LPIPS = lpips.LPIPS(net="vgg", verbose=False)

    def tensor(img):
        return torch.tensor(np.ascontiguousarray(img), dtype=torch.float32).permute(2, 0, 1)[None]

    with torch.no_grad():
        return float(_LPIPS(tensor(prediction_srgb), tensor(reference_srgb), normalize=True).item()), None


def lpips_unavailable() -> str | None:
    """Why LPIPS cannot be computed here, or None when it can."""
    try:
        import lpips  # noqa: F401
        import torch
    except ImportError as exc:
        return f"LPIPS unavailable: {exc.name} is not installed (pip install -e \".[lpips]\")"
    weights = os.path.join(torch.hub.get_dir(), "checkpoints")
    if not (os.path.isdir(weights) and any(f.startswith("vgg16") for f in os.listdir(weights))):
        return (f"LPIPS unavailable: torchvision's VGG16 weights are not in {weights} (it downloads them on "
                "first use; this machine may not reach the download)")
    return None


def flip_hdr(prediction: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> float:
    """Mean HDR-ꟻLIP error over ``mask`` (0 = identical) of linear images (H, W, 3), by NVIDIA's
    ``flip-evaluator`` with its default viewing conditions and exposure range."""
    import flip_evaluator

    error, _, _ = flip_evaluator.evaluate(np.ascontiguousarray(np.maximum(reference, 0), np.float32),
                                          np.ascontiguousarray(np.maximum(prediction, 0), np.float32), "HDR",
                                          applyMagma=False, computeMeanError=False)
    return float(np.asarray(error)[..., 0][mask].mean())


def stanford_orb(predictions: list, references: list, masks: list) -> dict:
    views = []
    for p, r, m in zip(predictions, references, masks):
        # an image file holds no negative value (an SH light's ringing); the reference stops on one
        p = np.maximum(p, 0.0)
        eroded = _orb_erode(m)
        psnr_h, _, _ = _orb_psnr(p, r, eroded, hdr=True)
        psnr_l, p_srgb, r_srgb = _orb_psnr(p, r, eroded, hdr=False)
        ssim = float(np.mean(np.clip(ssim_map(p_srgb, r_srgb, ORB_SSIM_WINDOW), -1.0, 1.0)))
        # the reference implementation encodes its sRGB images once more before LPIPS: kept
        score, reason = lpips_vgg(metrics.srgb_encode(p_srgb), metrics.srgb_encode(r_srgb))
        views.append({"psnr_h": psnr_h, "psnr_l": psnr_l, "ssim": ssim, "lpips_vgg": score,
                      **({"lpips_unavailable": reason} if reason else {})})
    return {"per_view": views}


def _masked_psnr_ssim(pred: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> dict:
    return {"psnr": metrics.psnr(pred, ref, mask, 1.0), "ssim": metrics.ssim(pred, ref, mask, 1.0)}


def _gamma(linear: np.ndarray) -> np.ndarray:
    """NeRFactor's encoding: values clipped to [0, 1], to the power 1/2.2."""
    return np.clip(linear, 0.0, 1.0) ** (1 / NERFACTOR_GAMMA)


def nerfactor(predictions: list, references: list, masks: list) -> dict:
    views = []
    for p, r, m in zip(predictions, references, masks):
        views.append(_masked_psnr_ssim(_gamma(metrics.align_scale(p, r, m)), _gamma(r), m))
    return {"per_view": views}


def tensoir(predictions: list, references: list, masks: list) -> dict:
    ratios = [r[m] / np.where(p[m] > 0, p[m], np.nan) for p, r, m in zip(predictions, references, masks)]
    stacked = np.concatenate(ratios) if ratios else np.zeros((0, 3))
    scale = np.nan_to_num(np.nanmedian(stacked, axis=0)) if np.isfinite(stacked).any() else np.zeros(3)
    views = [_masked_psnr_ssim(metrics.srgb_encode(p * scale), metrics.srgb_encode(r), m)
             for p, r, m in zip(predictions, references, masks)]
    return {"per_view": views, "set": {"scale": scale.tolist()}}


def raw(predictions: list, references: list, masks: list) -> dict:
    views = []
    for p, r, m in zip(predictions, references, masks):
        exposure = float(np.percentile(r[m], 99))
        views.append({"psnr_linear": metrics.psnr(p, r, m, float(r[m].max())),
                      "psnr_srgb": metrics.psnr(metrics.tonemap(p, exposure), metrics.tonemap(r, exposure), m, 1.0),
                      "flip_hdr": flip_hdr(p, r, m)})
    return {"per_view": views}


PROTOCOLS: dict[str, Protocol] = {p.name: p for p in (
    Protocol("stanford-orb", "per image and channel, least squares over the eroded mask",
             {"psnr_h": True, "psnr_l": True, "ssim": True, "lpips_vgg": False}, stanford_orb),
    Protocol("nerfactor", "per image and channel, least squares; gamma 1/2.2",
             {"psnr": True, "ssim": True}, nerfactor),
    Protocol("tensoir", "one scale per channel for the set: the median ratio of reference to prediction",
             {"psnr": True, "ssim": True}, tensoir),
    Protocol("raw", "none", {"psnr_linear": True, "psnr_srgb": True, "flip_hdr": False}, raw),
)}


def score(names: list[str], predictions: list, references: list, masks: list, protocols: tuple[str, ...]) -> dict:
    """Each protocol in ``protocols`` on one image set: {name: {"alignment", "higher_is_better",
    the mean of each metric over the views, "per_view": [{"name", metrics...}], set-level keys}}.
    A metric that could not be computed (LPIPS without its weights) is None, with the reason."""
    unknown = [p for p in protocols if p not in PROTOCOLS]
    if unknown:
        raise ValueError(f"unknown protocol(s) {unknown}; known: {sorted(PROTOCOLS)}")
    out = {}
    for name in protocols:
        protocol = PROTOCOLS[name]
        result = protocol.score(predictions, references, masks)
        views = result["per_view"]
        entry = {"alignment": protocol.alignment, "higher_is_better": protocol.higher_is_better}
        for key in protocol.higher_is_better:
            values = [v[key] for v in views if v.get(key) is not None]
            entry[key] = float(np.mean(values)) if values and len(values) == len(views) else None
        reasons = {v[k] for v in views for k in v if k.endswith("_unavailable")}
        if reasons:
            entry["unavailable"] = sorted(reasons)
        entry.update(result.get("set", {}))
        entry["per_view"] = [{"name": n, **v} for n, v in zip(names, views)]
        out[name] = entry
    return out
