"""When ``retinex-segmented`` ties a uniform region's faces to one albedo
(:func:`estimator.methods.retinex_segmented.edges.tied_regions`): a region of noise holds, with
the drift noise alone gives, and a texture chained into one region does not; faces join regions
from the segmentation under each light, until the assignment repeats."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from estimator import EstimatorConfig
from estimator.methods.retinex_segmented.edges import TIE_FITS, tied_regions
from estimator.methods.retinex_segmented.values import FitContext, Hypothesis, LightSource, Shading


def _one_region(albedo: np.ndarray, n: int) -> tuple[FitContext, Hypothesis]:
    """An n x n grid of faces (4-neighbour edges) under a coloured first-order light, every face
    in one region, with the per-face ``albedo`` (n * n, 3)."""
    y, x = np.mgrid[0:n, 0:n] / n
    normals = np.stack([np.sin(3 * x + 1), np.cos(2 * y), np.sin(2 * x + 3 * y)], -1).reshape(-1, 3)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    columns = np.column_stack([np.ones(n * n), 0.5 * normals])
    light = np.array([[2.0, 1.5, 1.0], [0.3, -0.2, 0.1], [-0.4, 0.1, 0.2], [0.5, 0.3, -0.1]])
    idx = np.arange(n * n).reshape(n, n)
    edges = np.concatenate([np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1),
                            np.stack([idx[:-1].ravel(), idx[1:].ravel()], 1)])
    usable = np.ones(n * n, bool)
    ctx = FitContext(SimpleNamespace(), EstimatorConfig(), None, "cauchy", None, edges, usable,
                     dict(loss="cauchy", iterations=30))
    h = Hypothesis(albedo * (columns @ light), light / light[0], Shading(columns), albedo, usable,
                   np.zeros(n * n, np.int64), 1, 1.0, LightSource.EDGES, None)
    return ctx, h


def _noisy(noise: float, n: int = 40, seed: int = 3) -> np.ndarray:
    """(n * n, 3) one albedo times log-normal noise of deviation ``noise`` per face and channel."""
    rng = np.random.default_rng(seed)
    return np.array([0.5, 0.3, 0.2]) * np.exp(rng.normal(0.0, noise, (n * n, 3)))


@pytest.mark.parametrize("noise", [0.01, 0.1])
def test_a_region_of_noise_holds(noise: float):
    """One region of 1,600 faces with independent Gaussian noise in log albedo: each face
    deviates from the region by sigma and from its neighbour by sqrt(2) sigma, so the drift is
    about 1 / sqrt(2) (a scale family: the ratio of the two medians tends to it). At 1 % the
    deviation is small too; at 10 % it exceeds ``region_max_deviation`` and the drift alone
    keeps the tie. Every face takes its region's albedo."""
    ctx, h = _one_region(_noisy(noise), 40)
    out = tied_regions(ctx, h)
    assert out.source is LightSource.EDGES_AND_REGIONS
    assert out.drift == pytest.approx(1 / np.sqrt(2), rel=0.15)
    assert (out.deviation > ctx.config.region_max_deviation) == (noise > 0.05)
    np.testing.assert_array_equal(out.labels, 0)
    assert np.ptp(out.albedo, axis=0).max() == 0


def test_a_texture_chained_into_one_region_keeps_its_albedos():
    """A smooth wave of +-0.5 in log albedo across the region (each face near its neighbours, far
    from the region's median) deviates beyond ``region_max_deviation`` and drifts beyond
    ``region_max_drift``: the hypothesis stays the edges' own, every face with its albedo."""
    n = 40
    albedo = _noisy(0.01, n) * np.exp(0.5 * np.sin(3 * np.pi * np.mgrid[0:n, 0:n][1].ravel() / n))[:, None]
    ctx, h = _one_region(albedo, n)
    out = tied_regions(ctx, h)
    assert out is h and out.source is LightSource.EDGES
    assert out.deviation > ctx.config.region_max_deviation and out.drift > ctx.config.region_max_drift
    np.testing.assert_array_equal(out.albedo, albedo)


def test_faces_join_regions_from_the_segmentation_each_fit(monkeypatch):
    """Faces outside the segmentation's regions join a region under each fitted light, from the
    segmentation's regions every time, and the light is fitted again until that assignment
    repeats: a face a first, rougher light joined to the wrong region is neither kept there nor
    tied in the light returned. A 20 x 20 grid: columns 0-9 of albedo A, 10-19 of albedo B; the
    segmentation found columns 0-7 (region 0) and 12-19 (region 1). The first tied fit
    (scripted) changes the shading of columns 8-11 through a second column, so that A's faces
    there look like B (brighter in red and green, darker in blue); the later fits' light is the
    true one. Every face ends in its true region with its region's albedo, and the last fit tied
    exactly those regions (the rule before kept columns 8-9 in B)."""
    n = 20
    col = np.tile(np.arange(n), n)
    a, b = np.array([0.6, 0.4, 0.3]), np.array([0.3, 0.3, 0.5])
    albedo = np.where((col < 10)[:, None], a, b)
    patch = ((col >= 8) & (col < 12)).astype(float)
    columns = np.column_stack([np.ones(n * n), patch])
    idx = np.arange(n * n).reshape(n, n)
    edges = np.concatenate([np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1),
                            np.stack([idx[:-1].ravel(), idx[1:].ravel()], 1)])
    usable = np.ones(n * n, bool)
    ctx = FitContext(SimpleNamespace(), EstimatorConfig(), None, "cauchy", None, edges, usable, {})
    segmented = np.where(col < 8, 0, np.where(col >= 12, 1, -1))
    truth = np.array([[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]])
    rough = np.array([[1.0, 1.0, 1.0], a / b - 1.0])   # A's faces in the patch look like B
    h = Hypothesis(albedo.copy(), truth, Shading(columns), albedo, usable, segmented, 2, 0.8, LightSource.EDGES, None)
    tied = []

    def scripted(radiance, columns, edges, usable, labels, **kwargs):
        tied.append(labels.copy())
        return (rough if len(tied) == 1 else truth), np.stack([a, b])

    monkeypatch.setattr("estimator.light.edge_fit.log_shading_fit", scripted)
    out = tied_regions(ctx, h)
    assert out.source is LightSource.EDGES_AND_REGIONS
    np.testing.assert_array_equal(out.labels, (col >= 10).astype(int))
    np.testing.assert_array_equal(tied[-1], out.labels)
    assert len(tied) == 3   # the segmentation's regions, the rough light's joins, the true light's
    np.testing.assert_allclose(out.albedo, albedo)


def test_a_tie_that_does_not_settle_keeps_the_regions_its_last_light_was_fitted_with(monkeypatch):
    """The assignment never repeats within TIE_FITS fits: a 12 x 12 grid of three regions by
    columns (A: 0-3, B: 4-7, C: 8-11), the segmentation leaving column 3 out. The first light is
    true (column 3 joins A), the second leaves C's faces unlit (C drops out of the assignment),
    the third is true again (C comes back). The tie returns the labels the third fit tied (A and
    B, C's faces on their own), their albedos from that fit's regions, and counts two regions;
    taking the last assignment, which the third light was not fitted with, would index a third
    region that fit never had."""
    n = 12
    col = np.tile(np.arange(n), n)
    palette = np.array([[0.6, 0.4, 0.3], [0.3, 0.3, 0.5], [0.2, 0.5, 0.2]])
    region = col // 4
    albedo = palette[region]
    columns = np.column_stack([np.ones(n * n), (region == 2).astype(float)])
    idx = np.arange(n * n).reshape(n, n)
    edges = np.concatenate([np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1),
                            np.stack([idx[:-1].ravel(), idx[1:].ravel()], 1)])
    usable = np.ones(n * n, bool)
    ctx = FitContext(SimpleNamespace(), EstimatorConfig(), None, "cauchy", None, edges, usable, {})
    segmented = np.where(col == 3, -1, region)
    true = np.array([[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]])
    dark = np.array([[1.0, 1.0, 1.0], [-0.999, -0.999, -0.999]])   # C's shading at 0.1 %: unlit
    h = Hypothesis(albedo.copy(), true, Shading(columns), albedo, usable, segmented, 3, 0.9, LightSource.EDGES, None)
    tied = []

    def scripted(radiance, columns, edges, usable, labels, **kwargs):
        tied.append(labels.copy())
        return (dark if len(tied) == 2 else true), palette[:int(labels.max()) + 1]

    monkeypatch.setattr("estimator.light.edge_fit.log_shading_fit", scripted)
    out = tied_regions(ctx, h)
    assert len(tied) == TIE_FITS == 3
    assert out.source is LightSource.EDGES_AND_REGIONS and out.regions == 2
    np.testing.assert_array_equal(out.labels, np.where(region == 2, -1, region))
    np.testing.assert_array_equal(tied[-1], out.labels)
    np.testing.assert_allclose(out.albedo, albedo)
