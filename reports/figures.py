"""Figures of a report (matplotlib, Agg): each function returns PNG bytes."""
from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from estimator import (  # noqa: E402
    Camera,  # noqa: E402
    RayCaster,  # noqa: E402
    latlong,
    sh,
)

from .metrics import LUMINANCE, lstsq_scale, tonemap  # noqa: E402


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def _show(ax, image, title):
    ax.imshow(np.clip(image, 0, 1), interpolation="nearest")
    ax.set_title(title, fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])


def _latlong_axes(ax, width: int, height: int) -> None:
    """Axes of a lat-long map in Mitsuba's envmap orientation: u across (0.5 faces +Z),
    elevation from +90 degrees (+Y, top row) to -90."""
    ax.set_xticks(np.linspace(-0.5, width - 0.5, 5), ["0", "0.25", "0.5 (+Z)", "0.75", "1"], fontsize=7)
    ax.set_yticks(np.linspace(-0.5, height - 0.5, 5), ["90", "45", "0", "-45", "-90"], fontsize=7)
    ax.set_xlabel("u (azimuth)", fontsize=8)
    ax.set_ylabel("elevation (deg)", fontsize=8)


def _tone_bar(fig, cax, exposure: float, label: str) -> None:
    """A colour bar, drawn into the axes ``cax``, of the report's tone map for grey values:
    linear values 0 .. ``exposure`` through the sRGB curve (white = ``exposure``), labelled with
    their units. (Colour bars get axes of their own in the grid: a layout engine placing them
    costs about half a second per figure, paid by every report.)"""
    from matplotlib.colors import ListedColormap, Normalize

    grey = tonemap(np.linspace(0, 1, 256), 1.0)
    bar = plt.cm.ScalarMappable(Normalize(0, exposure), ListedColormap(np.repeat(grey[:, None], 3, axis=1)))
    fig.colorbar(bar, cax=cax).set_label(label, fontsize=8)


def illumination(estimate_sh: np.ndarray, truth_sh: np.ndarray, size=(128, 256)) -> bytes:
    """Estimated vs filtered true pseudo illumination as lat-long maps (Mitsuba envmap
    orientation, shared exposure), and their energy per SH band (the paper's Fig. 5 a, b)."""
    est, tru = sh.to_latlong(estimate_sh, *size), sh.to_latlong(truth_sh, *size)
    exposure = float(np.percentile(np.maximum(tru, 0), 99.5))
    fig, axes = plt.subplots(1, 5, figsize=(14, 3.1), gridspec_kw={"width_ratios": [2, 2, 0.06, 0.3, 1.6],
                                                                    "wspace": 0.3})
    axes[3].set_visible(False)   # room for the colour bar's label
    _show(axes[0], tonemap(tru, exposure), "ground truth, Phong-filtered (unit DC)")
    _show(axes[1], tonemap(est, exposure), "estimated pseudo illumination")
    for ax in axes[:2]:
        _latlong_axes(ax, size[1], size[0])
    _tone_bar(fig, axes[2], exposure, "radiance (unit-DC gauge)")
    axes = [axes[0], axes[1], axes[4]]
    order = sh.order_of(estimate_sh.shape[0])
    band = sh.degrees(order)
    for coeffs, label in ((truth_sh, "truth"), (estimate_sh, "estimate")):
        axes[2].semilogy(
            range(order + 1), [np.sum(coeffs[band == l] ** 2) for l in range(order + 1)], "o-", label=label
        )
    axes[2].set_xlabel("SH band l")
    axes[2].set_ylabel("sum of squared coefficients")
    axes[2].set_title("energy per band", fontsize=9)
    axes[2].legend(fontsize=8)
    return _png(fig)


def ratio_histograms(ratios: dict[str, np.ndarray]) -> bytes:
    """Histograms of estimated / true albedo (luminance, DC gauge): the paper's Fig. 5e."""
    comps = [c for c in ("specular", "diffuse") if c in ratios]
    fig, axes = plt.subplots(1, max(1, len(comps)), figsize=(5.2 * max(1, len(comps)), 3.0), squeeze=False)
    for ax, comp in zip(axes[0], comps):
        r = ratios[comp][:, 3]
        r = r[np.isfinite(r)]
        ax.hist(np.clip(r, 0, 2), bins=np.linspace(0, 2, 101), color="#3b6ea5")
        for x, style in ((1.0, "-"), (0.95, ":"), (1.05, ":"), (0.9, "--"), (1.1, "--")):
            ax.axvline(x, color="k", lw=0.8, ls=style)
        ax.set_title(f"{comp}: estimated / true ({len(r)} faces)", fontsize=9)
        ax.set_xlabel("ratio (luminance, unit-DC gauge; clipped to [0, 2])")
        ax.set_ylabel("faces")
    if not comps:
        axes[0][0].text(0.5, 0.5, "no albedo to compare", ha="center")
    return _png(fig)


def face_latlong(caster: RayCaster, size=(90, 180)) -> np.ndarray:
    """(H, W) face hit by rays from the bounding-box centre outward (lat-long, envmap
    orientation), -1 where none: the texture map of a star-shaped mesh."""
    mesh = caster.mesh
    centre = 0.5 * (mesh.vertices.min(0) + mesh.vertices.max(0))
    dirs = latlong.directions(*size).reshape(-1, 3)
    return caster.first_hit_faces(np.broadcast_to(centre, dirs.shape).copy(), dirs).reshape(size)


def texture_maps(caster: RayCaster, estimate: dict[str, np.ndarray], truth: dict[str, np.ndarray]) -> bytes:
    """Estimated (scaled per channel by least squares) vs true per-face albedo as lat-long maps."""
    ids = face_latlong(caster)
    comps = list(estimate)
    fig, axes = plt.subplots(len(comps), 3, figsize=(11, 2.8 * len(comps)), squeeze=False,
                             gridspec_kw={"width_ratios": [1, 1, 0.04], "wspace": 0.25})
    for row, comp in zip(axes, comps):
        e, t = estimate[comp], truth[comp]
        s = lstsq_scale(e, t)
        top = max(float(np.percentile(t, 99.5)), 1e-6)
        for ax, values, title in ((row[0], t, f"true {comp} albedo"), (row[1], e * s, f"estimated {comp} (scaled)")):
            img = np.where(ids[..., None] >= 0, values[np.maximum(ids, 0)], 0.0)
            _show(ax, tonemap(img, top), title)
            _latlong_axes(ax, ids.shape[1], ids.shape[0])
        _tone_bar(fig, row[2], top, "albedo (linear; white = 99.5th pct of the truth)")
    return _png(fig)


def _palette(n: int) -> np.ndarray:
    rng = np.random.default_rng(12345)
    return np.clip(0.25 + 0.75 * rng.random((max(n, 1), 3)), 0, 1)


def clusters(caster: RayCaster, cameras: list[Camera], labels: np.ndarray, regions: np.ndarray | None) -> bytes:
    """Faces coloured by estimated cluster (and by true region) seen from a few cameras (Fig. 3)."""
    buffers = caster.face_id_buffers(cameras)
    rows = [("estimated clusters", labels)] + ([("true regions", regions)] if regions is not None else [])
    fig, axes = plt.subplots(len(rows), len(cameras), figsize=(2.6 * len(cameras), 2.6 * len(rows)), squeeze=False)
    for (title, lab), ax_row in zip(rows, axes):
        colours = _palette(int(lab.max()) + 2)
        for ax, ids in zip(ax_row, buffers):
            face_label = np.where(ids >= 0, lab[np.maximum(ids, 0)], -1)
            img = np.where((face_label >= 0)[..., None], colours[np.maximum(face_label, 0)], 0.0)
            img[(ids >= 0) & (face_label < 0)] = 0.35  # faces seen here but not estimated
            _show(ax, img, title)
    return _png(fig)


def image_comparison(names, predictions, references, masks, title: str) -> bytes:
    """Reference | prediction | difference, tone mapped with the reference's exposure."""
    n = len(names)
    fig, axes = plt.subplots(n, 5, figsize=(11, 2.8 * n), squeeze=False,
                             gridspec_kw={"width_ratios": [1, 1, 0.05, 1, 0.05], "wspace": 0.3})
    for row, name, p, r, m in zip(axes, names, predictions, references, masks):
        exposure = max(float(np.percentile(r[m], 99)) if m.any() else 1.0, 1e-30)
        s = lstsq_scale(p[m], r[m]) if m.any() else np.ones(3)
        _show(row[0], tonemap(r, exposure), f"{name}: reference")
        _show(row[1], tonemap(p * s, exposure), f"{title}")
        _tone_bar(fig, row[2], exposure, "radiance (scene units)")
        diff = np.abs(p * s - r) @ LUMINANCE / exposure
        im = row[3].imshow(np.where(m, diff, 0), cmap="magma", vmin=0, vmax=0.25)
        fig.colorbar(im, cax=row[4]).set_label("|difference| / exposure (luminance)", fontsize=8)
        row[3].set_title("difference (compared pixels)", fontsize=9)
        row[3].set_xticks([])
        row[3].set_yticks([])
    return _png(fig)


def compare_histograms(entries: list[tuple[str, np.ndarray]], component: str) -> bytes:
    """Overlaid ratio histograms of several runs (label, ratios (n,))."""
    fig, ax = plt.subplots(figsize=(7, 3.2))
    for label, r in entries:
        r = r[np.isfinite(r)]
        ax.hist(np.clip(r, 0, 2), bins=np.linspace(0, 2, 81), histtype="step", lw=1.4, density=True, label=label)
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_title(f"{component} albedo: estimated / true (unit-DC gauge)", fontsize=9)
    ax.set_xlabel("ratio (clipped to [0, 2])")
    ax.set_ylabel("density (faces per unit ratio)")
    ax.legend(fontsize=7)
    return _png(fig)


def error_against_time(runs: list[dict]) -> bytes:
    """Diffuse albedo PSNR against estimate time: runs are dicts with method, seconds, psnr
    and curve [(seconds, psnr), ...] (a line for a method that records its progress, a
    point per run otherwise); log time axis."""
    fig, ax = plt.subplots(figsize=(7, 3.4))
    colours, labelled = {}, set()
    for run in runs:
        colour = colours.setdefault(run["method"], f"C{len(colours) % 10}")
        label = None if run["method"] in labelled else run["method"]
        labelled.add(run["method"])
        if run["curve"]:
            t, p = zip(*run["curve"])
            ax.plot(t, p, color=colour, lw=1.2, alpha=0.8, label=label)
            label = None
        ax.plot([run["seconds"]], [run["psnr"]], "o", color=colour, ms=5, label=label)
    ax.set_xscale("log")
    ax.set_xlabel("estimate wall time (s)")
    ax.set_ylabel("diffuse PSNR (dB, lstsq scale)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return _png(fig)


def sweep_panels(axis: str, panels: list[tuple[str, dict]], columns: int = 4) -> bytes:
    """Plots in rows of ``columns``, a metric each: (metric label, label -> (x, mean, min,
    max)); a line per label with its min-max band. Non-numeric axis values are placed in order."""
    rows = -(-len(panels) // columns)
    fig, axes = plt.subplots(rows, min(columns, len(panels)), figsize=(4.0 * min(columns, len(panels)), 3.1 * rows),
                             squeeze=False, layout="constrained")
    for ax, (metric, series) in zip(axes.flat, panels):
        for label, (xs, mean, lo, hi) in series.items():
            try:
                pos = [float(x) for x in xs]
            except (TypeError, ValueError):
                pos = list(range(len(xs)))
                ax.set_xticks(pos, [str(x) for x in xs], rotation=30, fontsize=7)
            ax.plot(pos, mean, marker="o", label=label)
            ax.fill_between(pos, lo, hi, alpha=0.2)
        ax.set_xlabel(axis, fontsize=8)
        ax.set_ylabel(metric, fontsize=8)
        ax.set_title(metric, fontsize=9)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    axes[0][0].legend(fontsize=7)
    return _png(fig)


def face_values(caster: RayCaster, values: np.ndarray, title: str, log: bool = True) -> bytes:
    """One per-face scalar (F,) as a lat-long map of the mesh (NaN/inf and unseen: grey)."""
    ids = face_latlong(caster)
    v = np.asarray(values, float)
    shown = np.where(ids >= 0, v[np.maximum(ids, 0)], np.nan)
    shown[~np.isfinite(shown)] = np.nan
    if log:
        shown = np.log10(np.maximum(shown, 1e-6))
    fig, ax = plt.subplots(figsize=(8, 4))
    cmap = plt.get_cmap("viridis").with_extremes(bad=(0.5, 0.5, 0.5))
    im = ax.imshow(np.ma.masked_invalid(shown), cmap=cmap, interpolation="nearest")
    fig.colorbar(im, ax=ax, shrink=0.8, label=("log10 " if log else "") + title)
    ax.set_title(title, fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    return _png(fig)


def view_bars(names: list[str], residual: list, gross: list) -> bytes:
    """Per view: median relative residual and gross-error share (bars)."""
    x = np.arange(len(names))
    fig, axes = plt.subplots(1, 2, figsize=(max(6, 0.35 * len(names) + 4), 3))
    for ax, values, title in ((axes[0], residual, "median relative residual"),
                              (axes[1], gross, "share of gross errors (> 20 % of exposure)")):
        shown = [np.nan if v is None else v for v in values]
        ax.bar(x, shown)
        ax.set_title(title, fontsize=9)
        ax.set_xticks(x, [str(i) for i in range(len(names))], fontsize=7)
        ax.set_xlabel("view")
        ax.set_ylabel("share of the view's observations" if ax is axes[1] else "relative residual")
        if not np.nansum(shown):
            ax.text(0.5, 0.5, "none in any view", ha="center", va="center", transform=ax.transAxes, color="#555")
    return _png(fig)
