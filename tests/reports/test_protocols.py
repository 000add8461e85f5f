"""The published benchmarks' metric sets (reports/protocols.py): alignment, floors, SSIM window,
LPIPS's absence stated, errors. The Stanford-ORB numbers are checked against the benchmark's own
code by benchmarks/protocol_check.py (it needs PyTorch and kornia)."""
import sys

import numpy as np
import pytest

from estimator import PSNR_CAP_DB
from reports import protocols


def _scene(seed=0, size=24):
    rng = np.random.default_rng(seed)
    ref = rng.uniform(0.05, 1.5, (size, size, 3))
    pred = ref * rng.uniform(0.9, 1.1, ref.shape)
    mask = np.zeros((size, size), bool)
    mask[3:-3, 4:-2] = True
    return pred, ref, mask


def test_identical_images_score_perfectly():
    _, ref, mask = _scene()
    out = protocols.score(["a"], [ref], [ref], [mask], tuple(protocols.PROTOCOLS))
    orb = out["stanford-orb"]
    # PSNR_CAP_DB: the project's PSNR of an exact match
    # kornia's 1e-12 in the SSIM's denominator leaves 1 - 1.2e-5 on the empty background
    assert orb["psnr_h"] == orb["psnr_l"] == PSNR_CAP_DB and orb["ssim"] == pytest.approx(1.0, abs=2e-5)
    assert out["nerfactor"]["ssim"] == pytest.approx(1.0, abs=1e-9) and out["nerfactor"]["psnr"] == PSNR_CAP_DB
    assert out["tensoir"]["scale"] == pytest.approx([1, 1, 1])
    assert out["raw"]["flip_hdr"] == pytest.approx(0.0, abs=1e-6) and out["raw"]["psnr_linear"] == PSNR_CAP_DB
    assert out["raw"]["per_view"][0]["name"] == "a"


def test_aligned_protocols_ignore_a_scale_per_channel_and_raw_does_not():
    pred, ref, mask = _scene()
    gain = np.array([2.0, 0.5, 3.0])
    plain = protocols.score(["v"], [pred], [ref], [mask], tuple(protocols.PROTOCOLS))
    scaled = protocols.score(["v"], [pred * gain], [ref], [mask], tuple(protocols.PROTOCOLS))
    for name, key in (("stanford-orb", "psnr_h"), ("stanford-orb", "psnr_l"), ("stanford-orb", "ssim"),
                      ("nerfactor", "psnr"), ("tensoir", "psnr"), ("tensoir", "ssim")):
        assert scaled[name][key] == pytest.approx(plain[name][key], abs=1e-6), (name, key)
    assert scaled["raw"]["psnr_linear"] < plain["raw"]["psnr_linear"] - 5
    assert scaled["raw"]["flip_hdr"] > plain["raw"]["flip_hdr"]
    assert np.allclose(scaled["tensoir"]["scale"], np.array(plain["tensoir"]["scale"]) / gain)


def test_tensoir_takes_one_scale_for_the_whole_set():
    pred, ref, mask = _scene()
    two = protocols.tensoir([pred, pred * 2], [ref, ref], [mask, mask])
    one = protocols.tensoir([pred], [ref], [mask])
    # one scale serves both views: the second, twice as bright, cannot be scored as the first
    assert two["per_view"][1]["psnr"] < one["per_view"][0]["psnr"] - 3


def test_orb_psnr_has_the_grey_floor_and_counts_the_background():
    _, ref, mask = _scene()
    black = np.zeros_like(ref)
    psnr_l, _, r = protocols._orb_psnr(black, ref, mask, hdr=False)
    grey = np.mean((0.5 * mask[..., None] - r) ** 2)
    assert psnr_l == pytest.approx(-10 * np.log10(grey))
    # the mean runs over the whole image: a larger empty border raises the PSNR of the same error
    pred, ref, mask = _scene(1)
    padded = [np.pad(x, ((0, 24), (0, 0), (0, 0))) for x in (pred, ref)]
    small = protocols._orb_psnr(pred, ref, mask, hdr=True)[0]
    large = protocols._orb_psnr(*padded, np.pad(mask, ((0, 24), (0, 0))), hdr=True)[0]
    assert large == pytest.approx(small + 10 * np.log10(2), abs=1e-9)


def test_orb_erosion_keeps_the_image_border_and_shrinks_holes():
    full = np.ones((10, 10), bool)
    assert protocols._orb_erode(full).all()
    holed = full.copy()
    holed[5, 5] = False
    eroded = protocols._orb_erode(holed)
    assert not eroded[3:8, 3:8].any() and eroded.sum() == 100 - 25


def test_ssim_map_matches_the_formula_at_a_pixel():
    rng = np.random.default_rng(3)
    a, b = rng.uniform(0, 1, (2, 6, 6, 3))
    got = protocols.ssim_map(a, b, 3)
    # the 3 x 3 Gaussian (sigma 1.5) window around pixel (2, 3), written out
    w = np.exp(-np.array([1.0, 0.0, 1.0]) / (2 * 1.5 ** 2))
    w = np.outer(w, w) / np.outer(w, w).sum()
    pa, pb = a[1:4, 2:5, 0], b[1:4, 2:5, 0]
    ma, mb = (w * pa).sum(), (w * pb).sum()
    va, vb, cov = (w * pa * pa).sum() - ma ** 2, (w * pb * pb).sum() - mb ** 2, (w * pa * pb).sum() - ma * mb
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    expected = (2 * ma * mb + c1) * (2 * cov + c2) / ((ma ** 2 + mb ** 2 + c1) * (va + vb + c2))
    assert got[2, 3, 0] == pytest.approx(expected, rel=1e-9)
    # at the border the row beyond is the one inside, reflected without repeating the edge
    reflected = np.concatenate([a[1:2], a], axis=0), np.concatenate([b[1:2], b], axis=0)
    assert got[0, 3, 1] == pytest.approx(protocols.ssim_map(*reflected, 3)[1, 3, 1], rel=1e-9)


def test_lpips_is_stated_unavailable_with_its_reason(monkeypatch):
    monkeypatch.setitem(sys.modules, "lpips", None)   # as on a machine without the extra
    pred, ref, mask = _scene()
    out = protocols.score(["v"], [pred], [ref], [mask], ("stanford-orb",))["stanford-orb"]
    assert out["lpips_vgg"] is None and out["per_view"][0]["lpips_vgg"] is None
    assert out["unavailable"] == ["LPIPS unavailable: lpips is not installed (pip install -e \".[lpips]\")"]
    assert out["higher_is_better"]["lpips_vgg"] is False and np.isfinite(out["psnr_h"])


def test_negative_predictions_are_clipped_for_the_orb_protocol():
    pred, ref, mask = _scene()
    ringing = pred.copy()
    ringing[5, 5] = -0.3
    clipped = pred.copy()
    clipped[5, 5] = 0.0
    a = protocols.stanford_orb([ringing], [ref], [mask])["per_view"][0]
    b = protocols.stanford_orb([clipped], [ref], [mask])["per_view"][0]
    assert a["psnr_h"] == b["psnr_h"] and a["ssim"] == b["ssim"]


def test_unknown_protocol_is_named():
    pred, ref, mask = _scene()
    with pytest.raises(ValueError, match="unknown protocol.*'orb'.*known"):
        protocols.score(["v"], [pred], [ref], [mask], ("orb",))
