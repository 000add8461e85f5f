"""Numbers that compare an estimate with ground truth."""
from __future__ import annotations

import numpy as np
from scipy.special import comb

from estimator import InputError, psnr_db, sh


def adjusted_rand_index(truth: np.ndarray, labels: np.ndarray) -> float:
    """Adjusted Rand index (Hubert & Arabie 1985) of two labelings (N,); 1 = same partition."""
    truth, labels = np.asarray(truth), np.asarray(labels)
    if truth.shape != labels.shape or truth.ndim != 1 or not len(truth):
        raise InputError(f"labelings must be 1-D of one length > 0, got {truth.shape} and {labels.shape}")
    _, t = np.unique(truth, return_inverse=True)
    _, l = np.unique(labels, return_inverse=True)
    table = np.zeros((t.max() + 1, l.max() + 1), dtype=np.int64)
    np.add.at(table, (t, l), 1)
    index = comb(table, 2).sum()
    rows, cols = comb(table.sum(1), 2).sum(), comb(table.sum(0), 2).sum()
    total = comb(len(truth), 2)
    expected = rows * cols / total if total > 0 else 0.0
    maximum = 0.5 * (rows + cols)
    if maximum == expected:
        return 1.0
    return float((index - expected) / (maximum - expected))


LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec.709 / sRGB luminance weights (linear RGB)
SCALES = ("dc", "lstsq", "robust")
GROSS_FACTOR = 2.0   # a face whose scaled albedo is off by more than this factor is a gross error, set aside


def robust_scale(values: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel scale that a few faces cannot overturn, and the faces it set aside.

    The median of the per-face ratios reference / values starts it; faces whose scaled
    luminance is off by more than :data:`GROSS_FACTOR` are set aside (luminance, so a channel
    that is zero in a saturated colour is no gross error); the least-squares scale of the rest
    is the result (the Stanford-ORB scale on the faces that are not gross errors).
    values, reference : (N, C) -> ((C,), (N,) bool set aside).
    """
    v, r = np.asarray(values, float), np.asarray(reference, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where((v > 0) & (r > 0), r / v, np.nan)
    start = np.array([np.nanmedian(ratio[:, c]) if np.any(np.isfinite(ratio[:, c])) else 1.0
                      for c in range(v.shape[1])])
    scaled, true = (v * start) @ LUMINANCE[: v.shape[1]], r @ LUMINANCE[: v.shape[1]]
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.abs(np.log(np.where((true > 0) & (scaled > 0), scaled / true, np.nan)))
    aside = (np.nan_to_num(off, nan=np.inf) > np.log(GROSS_FACTOR)) & (true > 0)
    keep = ~aside if np.any(~aside) else np.ones(len(v), bool)
    return lstsq_scale(v[keep], r[keep]), aside


def lstsq_scale(values: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Per-channel least-squares scale s minimising ||s values - reference||.

    values, reference : (N, C) -> (C,); 1 where ``values`` is all zero in a channel. A negative
    scale is refused: the estimate runs against the truth in that channel, and flipping it
    would score a negated estimate as perfect.
    """
    v, r = np.asarray(values, float), np.asarray(reference, float)
    num, den = np.sum(v * r, axis=0), np.sum(v * v, axis=0)
    scale = np.where(den > 0, num / np.where(den > 0, den, 1.0), 1.0)
    if np.any(scale < 0):
        raise InputError(f"the estimate runs against the truth in channel(s) {np.nonzero(scale < 0)[0].tolist()}: "
                         "its least-squares gauge would be negative")
    return scale


def _compared(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The masked rows of ``estimate`` and ``truth`` (F, 3) as float arrays, refusing what would
    score wrongly without a word: shapes that differ, a mask that is not (F,) bool (0/1
    integers would index faces 0 and 1), and non-finite estimated albedos (one turns every
    ratio to NaN)."""
    e, t, m = np.asarray(estimate, float), np.asarray(truth, float), np.asarray(mask)
    if e.shape != t.shape or e.ndim != 2:
        raise InputError(f"estimate and truth must be albedos of one shape (F, C), got {e.shape} and {t.shape}")
    if m.dtype != bool or m.shape != (len(e),):
        raise InputError(f"mask must be ({len(e)},) bool, got {m.shape} {m.dtype}")
    e, t = e[m], t[m]
    bad = ~np.all(np.isfinite(e), axis=1)
    if bad.any():
        raise InputError(f"{int(bad.sum())} compared face(s) have a non-finite estimated albedo (first: "
                         f"row {int(np.nonzero(m)[0][np.argmax(bad)])}); mark them unestimated before scoring")
    return e, t


def albedo_ratios(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray, scale: str,
                  dc: np.ndarray | None = None) -> np.ndarray:
    """Per-face ratio estimated / true albedo, after removing one global scale.

    Parameters
    ----------
    estimate, truth : (F, 3) linear albedo.
    mask : (F,) faces to compare.
    scale : 'dc' -- the estimate is in the unit-DC gauge of its illumination, so
        the truth is brought into the same gauge by multiplying it by the DC
        coefficient of the true illumination per channel (``dc`` (3,)); nothing is
        fitted (the paper's normalisation). 'lstsq' -- a per-channel least-squares
        scale s_c = sum(e t) / sum(e^2) fitted on the masked faces (Stanford-ORB).
        'robust' -- :func:`robust_scale`: the least-squares scale of the faces that are not
        gross errors, which a handful of absurd faces cannot move.

    Returns
    -------
    (n, 4) ratios per channel R, G, B and of the luminance, for the n masked faces.
    """
    if scale not in SCALES:
        raise InputError(f"scale must be one of {SCALES}, got {scale!r}")
    e, t = _compared(estimate, truth, mask)
    if scale == "dc":
        if dc is None:
            raise InputError("scale 'dc' needs the DC coefficient of the true illumination")
        t = t * np.asarray(dc, float)[None]
    elif scale == "lstsq":
        e = e * lstsq_scale(e, t)[None]
    else:   # 'robust'
        e = e * robust_scale(e, t)[0][None]
    with np.errstate(divide="ignore", invalid="ignore"):
        per_channel = np.where(t > 0, e / t, np.nan)
        lum = (e @ LUMINANCE) / (t @ LUMINANCE)
    return np.column_stack([per_channel, lum])


def albedo_psnr(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray, gauge: str = "lstsq") -> float | None:
    """PSNR (dB, peak 1) of per-face albedo (F, 3) over every masked face after a per-channel
    scale of the estimate onto the truth (the albedo/light gauge): 'lstsq' (:func:`lstsq_scale`)
    or 'robust' (:func:`robust_scale`: only the scale ignores the gross errors)."""
    if gauge not in ("lstsq", "robust"):
        raise InputError(f"gauge must be 'lstsq' or 'robust', got {gauge!r}")
    e, t = _compared(estimate, truth, mask)
    if e.size == 0:
        return None
    scale = lstsq_scale(e, t) if gauge == "lstsq" else robust_scale(e, t)[0]
    mse = float(np.mean((e * scale[None] - t) ** 2))
    return psnr_db(mse, 1.0)


def ratio_summary(ratios: np.ndarray) -> dict:
    """Median, inter-quartile range and share within +-5 % / +-10 % of finite ratios (n,)."""
    r = np.asarray(ratios, float)
    r = r[np.isfinite(r)]
    if r.size == 0:
        return {"count": 0, "median_ratio": None, "iqr": None, "within_5": None, "within_10": None}
    q1, med, q3 = np.percentile(r, [25, 50, 75])
    return {"count": int(r.size), "median_ratio": float(med), "iqr": float(q3 - q1),
            "within_5": float(np.mean(np.abs(r - 1) <= 0.05)), "within_10": float(np.mean(np.abs(r - 1) <= 0.10))}


def sh_comparison(estimate: np.ndarray, truth: np.ndarray) -> dict:
    """Relative L2 error and per-band energy of two SH sets ((L + 1)^2, C), same gauge."""
    e, t = np.asarray(estimate, float), np.asarray(truth, float)
    if e.shape != t.shape:
        raise InputError(f"SH shapes differ: {e.shape} vs {t.shape}")
    if not np.any(t):
        raise InputError("the true SH light is zero: no relative error is defined")
    order = sh.order_of(e.shape[0])
    band = sh.degrees(order)
    energy = lambda c: [float(np.sum(c[band == l] ** 2)) for l in range(order + 1)]  # noqa: E731
    err = [float(np.linalg.norm((e - t)[band == l]) / max(np.linalg.norm(t[band == l]), 1e-300))
           for l in range(order + 1)]
    return {"sh_order": order, "relative_l2": float(np.linalg.norm(e - t) / max(np.linalg.norm(t), 1e-300)),
            "band_energy_estimate": energy(e), "band_energy_truth": energy(t), "band_relative_l2": err}


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """sRGB transfer function of linear values clipped to [0, 1]."""
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_decode(encoded: np.ndarray) -> np.ndarray:
    """Inverse of :func:`srgb_encode`: sRGB-encoded values in [0, 1] -> linear values."""
    x = np.asarray(encoded, dtype=np.float64)
    return np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4))


def tonemap(linear: np.ndarray, exposure: float) -> np.ndarray:
    """The report's tone map: sRGB encoding of min(1, x / exposure)."""
    return srgb_encode(np.asarray(linear, float) / max(exposure, 1e-300))


def align_scale(prediction: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Per-channel least-squares scale of ``prediction`` onto ``reference`` over ``mask`` (H, W)."""
    return prediction * lstsq_scale(prediction[mask], reference[mask])[None, None]


def psnr(prediction: np.ndarray, reference: np.ndarray, mask: np.ndarray, peak: float) -> float:
    """PSNR (dB) over the masked pixels with the given peak (:func:`estimator.psnr_db`)."""
    if not np.any(mask):
        raise InputError("PSNR over no pixel: the mask is empty")
    return psnr_db(float(np.mean((prediction[mask] - reference[mask]) ** 2)), peak)


def ssim(prediction: np.ndarray, reference: np.ndarray, mask: np.ndarray, peak: float) -> float:
    """Mean SSIM (Wang et al. 2004: Gaussian window sigma 1.5, K1 0.01, K2 0.03, population
    covariance) per channel, by scikit-image's ``structural_similarity``; the SSIM map is
    averaged over the masked pixels (H, W). Outside the mask the prediction takes the
    reference's values, so that a window straddling the mask's edge (the background, a face
    the estimate left out) compares the masked pixels alone."""
    from skimage.metrics import structural_similarity

    prediction = np.where(mask[..., None], prediction, reference)
    _, full = structural_similarity(prediction.astype(np.float64), reference.astype(np.float64),
                                    data_range=peak, channel_axis=2, gaussian_weights=True, sigma=1.5,
                                    use_sample_covariance=False, full=True)
    return float(np.mean(full[mask]))


def image_metrics(prediction: np.ndarray, reference: np.ndarray, mask: np.ndarray, align: bool = True) -> dict:
    """PSNR, SSIM and relative L2 of a predicted linear image against a reference, on the object's pixels.

    With ``align`` the prediction is first scaled per channel by least squares
    over the mask (the estimate's albedo/light scale is a gauge). 'linear': HDR values, peak =
    max of the reference. 'srgb':
    both tone mapped with exposure = 99th percentile of the reference's
    masked values, peak 1.
    """
    if not mask.any():
        raise InputError("no pixel to compare: the object covers none of the reference image")
    if min(reference.shape[:2]) < 7:   # SSIM's Gaussian window (sigma 1.5) spans 7 x 7 pixels
        raise InputError(f"images must be at least 7 x 7 pixels for SSIM's window, got {reference.shape[:2]}")
    if prediction.shape != reference.shape:
        raise InputError(f"prediction {prediction.shape} and reference {reference.shape} differ in shape")
    pred = align_scale(prediction, reference, mask) if align else prediction
    peak = float(reference[mask].max())
    exposure = float(np.percentile(reference[mask], 99))
    tp, tr = tonemap(pred, exposure), tonemap(reference, exposure)
    return {"psnr_linear": psnr(pred, reference, mask, peak), "ssim_linear": ssim(pred, reference, mask, peak),
            "psnr_srgb": psnr(tp, tr, mask, 1.0), "ssim_srgb": ssim(tp, tr, mask, 1.0),
            "relative_l2": float(np.linalg.norm(pred[mask] - reference[mask]) / np.linalg.norm(reference[mask]))}


def ciede2000(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """CIEDE2000 colour difference of linear Rec.709 albedos (N, 3) (D65, 2 degree observer)."""
    import colour

    space = colour.RGB_COLOURSPACES["ITU-R BT.709"]
    white = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]

    def lab(rgb):
        return colour.XYZ_to_Lab(colour.RGB_to_XYZ(np.clip(rgb, 0, None), space, apply_cctf_decoding=False), white)

    return np.asarray(colour.delta_E(lab(estimate), lab(truth), method="CIE 2000"), dtype=np.float64)


IRRADIANCE_ORDER = 2          # the clamped cosine keeps > 99 % of irradiance energy in degrees 0-2
IRRADIANCE_NORMALS = 2562     # normals of the irradiance comparison (a Fibonacci sphere)
LATLONG_SIZE = (33, 64)       # rows, columns of the lat-long maps compared
DIRECTION_SAMPLES = 20000     # directions searched for a light's brightest point (~1.6 degree spacing)
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])   # Rec. 709


def _scaled(estimate: np.ndarray, truth: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """``estimate`` (N, 3) times the per-channel least-squares scale onto ``truth`` (the gauge),
    each row weighted by ``weights`` (N,) when given."""
    root = np.ones((len(truth), 1)) if weights is None else np.sqrt(weights)[:, None]
    return estimate * lstsq_scale(root * estimate, root * truth)


def irradiance_error(estimate_radiance: np.ndarray, true_radiance: np.ndarray) -> float:
    """Relative L2, over a sphere of normals, of the irradiance the estimated light gives
    against the true light's (both radiance SH (M, 3)), after one scale per channel.

    Irradiance is the radiance filtered by the clamped cosine, whose SH filter is pi times
    the Phong filter of exponent 1 (Ramamoorthi & Hanrahan), taken to degree
    :data:`IRRADIANCE_ORDER`: what a matte surface sees of the light, whatever its detail.
    """
    order = IRRADIANCE_ORDER
    kernel = np.pi * sh.expand_per_degree(sh.phong_filter(order, 1.0))[:, None]
    basis = sh.basis(order, sh.fibonacci_sphere(IRRADIANCE_NORMALS))
    m = sh.num_coeffs(order)
    def padded(radiance):   # a light of a lower order has zeros above it
        out = np.zeros((m, 3))
        out[: min(m, len(radiance))] = np.asarray(radiance, float)[:m]
        return out

    e, t = basis @ (kernel * padded(estimate_radiance)), basis @ (kernel * padded(true_radiance))
    if not np.any(t):
        raise InputError("the true light gives no irradiance: no relative error is defined")
    return float(np.linalg.norm(_scaled(e, t) - t) / max(np.linalg.norm(t), 1e-300))


def latlong_psnr(estimate: np.ndarray, truth: np.ndarray) -> float:
    """PSNR (dB, peak: the true map's maximum) of the estimated light's lat-long map against
    the true one's (SH (M, 3) each, same filter), after one scale per channel, each pixel
    weighted by its solid angle."""
    from estimator.core import latlong

    h, w = LATLONG_SIZE
    weights = latlong.solid_angles(h, w).reshape(-1)
    e = sh.to_latlong(estimate, h, w).reshape(-1, 3)
    t = sh.to_latlong(truth, h, w).reshape(-1, 3)
    if not t.max() > 0:
        raise InputError("the true light's lat-long map has no positive value: no PSNR is defined")
    mse = float(np.sum(weights[:, None] * (_scaled(e, t, weights) - t) ** 2) / (3 * weights.sum()))
    return psnr_db(mse, float(t.max()))


def brightest_direction(coeffs: np.ndarray) -> np.ndarray:
    """(3,) unit direction where the SH light (M, 3) is brightest in luminance."""
    dirs = sh.fibonacci_sphere(DIRECTION_SAMPLES)
    values = sh.basis(sh.order_of(coeffs.shape[0]), dirs) @ coeffs @ LUMINANCE
    return dirs[int(np.argmax(values))]


def direction_error_deg(estimate: np.ndarray, to_sun: np.ndarray) -> float:
    """Angle (degrees) between the estimated light's brightest direction and the true sun's."""
    d = brightest_direction(estimate)
    s = np.asarray(to_sun, float) / np.linalg.norm(to_sun)
    return float(np.degrees(np.arccos(np.clip(d @ s, -1.0, 1.0))))
