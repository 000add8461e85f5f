"""Sweep results: one plot per (scene, sweep axis) of each headline metric against the axis
value, one line per method, the mean with its spread (min to max) over seeds and the other
axes; written as sweep.json and a self-contained sweep.html."""
from __future__ import annotations

import html
import json
import os

import numpy as np

from . import figures
from .html import embed_png

SWEEP_METRICS = [  # (label, key in a sweep row)
    ("diffuse ±10 % (lstsq)", "albedo.diffuse.lstsq.luminance.within_10"),
    ("specular ±10 % (lstsq)", "albedo.specular.lstsq.luminance.within_10"),
    ("diffuse PSNR, lstsq (dB)", "albedo.diffuse.psnr_lstsq"),
    ("novel PSNR sRGB (dB)", "novel_views.psnr_srgb"),
    ("estimate time (s)", "seconds"),
]


def _sortable(values: list) -> list:
    try:
        return sorted(values, key=float)
    except (TypeError, ValueError):
        return sorted(values, key=str)


def _key(value):
    """A hashable stand-in for an axis value (lists and tables as their JSON)."""
    return json.dumps(value, sort_keys=True) if isinstance(value, (list, dict)) else value


def axis_series(rows: list[dict], scene: str, axis: str, key: str) -> dict[str, tuple[list, list, list, list]]:
    """label -> (x values, mean, min, max) of ``key`` over the rows of ``scene``, grouped by
    the value of ``axis`` (rows without the metric are skipped)."""
    out = {}
    sel = [r for r in rows if r["scene"] == scene and axis in r["axes"] and r.get(key) is not None]
    for label in dict.fromkeys(r["label"] for r in sel):
        xs = _sortable(list(dict.fromkeys(_key(r["axes"][axis]) for r in sel if r["label"] == label)))
        values = [[r[key] for r in sel if r["label"] == label and _key(r["axes"][axis]) == x] for x in xs]
        out[label] = (xs, [float(np.mean(v)) for v in values], [float(np.min(v)) for v in values],
                      [float(np.max(v)) for v in values])
    return out


def write(folder: str, name: str, rows: list[dict]) -> None:
    """sweep.json (the rows) and sweep.html (the plots and a table) into ``folder``."""
    os.makedirs(folder, exist_ok=True)
    _atomic_text(os.path.join(folder, "sweep.json"), json.dumps({"suite": name, "rows": rows}, indent=1, default=str))
    name = str(name)
    parts = [f"<html><head><meta charset='utf-8'><title>{html.escape(name)} sweep</title></head><body>",
             f"<h1>Sweep: {html.escape(name)}</h1>"]
    for scene in dict.fromkeys(r["scene"] for r in rows):
        axes = list(dict.fromkeys(a for r in rows if r["scene"] == scene for a in r["axes"]))
        for axis in axes:
            panels = [(label, axis_series(rows, scene, axis, key)) for label, key in SWEEP_METRICS]
            panels = [(label, series) for label, series in panels if series]
            if panels:
                parts.append(f"<h2>{html.escape(scene)}: {html.escape(axis)}</h2>")
                parts.append(embed_png(figures.sweep_panels(axis, panels), f"{scene} {axis}"))
    header = ["scene", "method", "seed", "axes"] + [label for label, _ in SWEEP_METRICS]
    parts.append("<table border='1'><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr>")
    for r in rows:
        cells = [r["scene"], r["label"], r["seed"], json.dumps(r["axes"])] + [
            "-" if r.get(key) is None else f"{r[key]:.3f}" for _, key in SWEEP_METRICS]
        parts.append("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in cells) + "</tr>")
    parts.append("</table></body></html>")
    _atomic_text(os.path.join(folder, "sweep.html"), "\n".join(parts))


def _atomic_text(path: str, text: str) -> None:
    tmp = f"{path}.tmp-{os.getpid()}"
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, path)
