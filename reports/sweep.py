"""Sweep results: one plot per (scene, sweep axis) of each headline metric against the axis
value, one line per method, the mean with its spread (min to max) over seeds and the other
axes; written as sweep.json and a self-contained sweep.html."""
from __future__ import annotations

import html
import json
import os

import numpy as np

from estimator import InputError

from . import figures
from .html import LEADERBOARD_NOTE, SORT_SCRIPT, STYLE, embed_png, leaderboard
from .regression import TRACKED, check
from .report import sweep_values

SWEEP_METRICS = [  # (label, key in a sweep row)
    ("diffuse ±10 % (lstsq)", "albedo.diffuse.lstsq.luminance.within_10"),
    ("specular ±10 % (lstsq)", "albedo.specular.lstsq.luminance.within_10"),
    ("diffuse PSNR, lstsq (dB)", "albedo.diffuse.psnr_lstsq"),
    # the robust gauge (scale from the faces that are not gross errors): a handful of outlier
    # faces sink the least-squares gauge's figures, not these
    ("diffuse ±10 % (robust)", "albedo.diffuse.robust.luminance.within_10"),
    ("specular ±10 % (robust)", "albedo.specular.robust.luminance.within_10"),
    ("diffuse PSNR, robust (dB)", "albedo.diffuse.psnr_robust"),
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


def row_key(row: dict) -> str:
    """The identity of a sweep row across versions: scene, method label, seed and axis values."""
    return json.dumps([row["scene"], row["label"], row["seed"], row["axes"]], sort_keys=True, default=str)


def regressions(rows: list[dict], baseline_rows: list[dict]) -> list[dict]:
    """Each row's tracked metrics (:data:`reports.regression.TRACKED`, the ones a sweep row
    holds) against the baseline sweep's row of the same :func:`row_key`, by
    :func:`reports.regression.check`: one entry per (row, metric) with status 'ok', 'worse'
    or 'missing', and the row's key; rows new to this sweep are skipped."""
    base = {row_key(r): r for r in baseline_rows}
    out = []
    for row in rows:
        old = base.get(row_key(row))
        if old is None:
            continue
        kept = {m: float(old[m]) for m in TRACKED if isinstance(old.get(m), (int, float))
                and not isinstance(old[m], bool) and np.isfinite(old[m])}
        out += [{"row": row_key(row), **r} for r in check(_nested(row), {"metrics": kept})]
    return out


def _nested(row: dict) -> dict:
    """A sweep row (flat dotted metric keys) as the nested dict that reports hold."""
    out: dict = {}
    for key, value in row.items():
        *parents, leaf = key.split(".")
        node = out
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    return out


def read_rows(path: str) -> list[dict]:
    """The rows of a sweep.json (a previous sweep: the baseline)."""
    try:
        with open(path) as f:
            data = json.load(f)
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: not a readable sweep.json ({exc})") from None
    except RecursionError:   # Python's parser recurses once per nesting level
        raise InputError(f"{path}: not a readable sweep.json (its JSON is nested too deeply)") from None
    rows = data.get("rows") if isinstance(data, dict) else None
    if not isinstance(rows, list) or not all(isinstance(r, dict) and {"scene", "label", "seed", "axes"} <= set(r)
                                             for r in rows):
        raise InputError(f"{path}: a sweep.json holds 'rows' with scene, label, seed and axes")
    return rows


def write(folder: str, name: str, rows: list[dict], verdict: list[dict] | None = None) -> None:
    """sweep.json (the rows) and sweep.html (the plots and a table) into ``folder``; with
    ``verdict`` (:func:`regressions`) also regression.json and a regression section."""
    os.makedirs(folder, exist_ok=True)
    _atomic_text(os.path.join(folder, "sweep.json"), json.dumps({"suite": name, "rows": rows}, indent=1, default=str))
    name = str(name)
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(name)} sweep</title>"
             f"<style>{STYLE}</style>{SORT_SCRIPT}</head><body>", f"<h1>Sweep: {html.escape(name)}</h1>",
             f"<p class='note'>{len(rows)} runs; plots: the mean over seeds (and the sweep's other axes) with "
             "a band from the lowest to the highest value.</p>"]
    if verdict is not None:
        worse = [v for v in verdict if v["status"] != "ok"]
        _atomic_text(os.path.join(folder, "regression.json"),
                     json.dumps({"compared": len(verdict), "worse": len(worse), "rows": verdict}, indent=1))
        parts.append(f"<h2>Regression against the baseline sweep: {len(verdict) - len(worse)} of {len(verdict)} "
                     "tracked metrics within tolerance</h2>")
        if worse:
            parts.append(
                "<table><tr><th>row</th><th>metric</th><th>baseline</th><th>now</th></tr>"
                + "".join(
                    f"<tr><td>{html.escape(v['row'])}</td><td>{html.escape(v['metric'])}</td><td>{v['baseline']:.4g}</td>"
                    f"<td class='bad'>{'missing' if v['current'] is None else format(v['current'], '.4g')}</td></tr>"
                    for v in worse
                )
                + "</table>"
            )
    parts += ["<h2>Over seeds</h2>", LEADERBOARD_NOTE,
              leaderboard(TABLE_COLUMNS[:3] + [("seeds", "seeds")]
                          + [(f"{label} (mean ± sd)", key) for label, key in SWEEP_METRICS],
                          over_seeds(rows))]
    for scene in dict.fromkeys(r["scene"] for r in rows):
        axes = list(dict.fromkeys(a for r in rows if r["scene"] == scene for a in r["axes"]))
        for axis in axes:
            panels = [(label, axis_series(rows, scene, axis, key)) for label, key in SWEEP_METRICS]
            panels = [(label, series) for label, series in panels if series]
            if panels:
                parts.append(f"<h2>{html.escape(scene)}: {html.escape(axis)}</h2>")
                parts.append(embed_png(figures.sweep_panels(axis, panels), f"{scene} {axis}"))
    parts += ["<h2>Every run</h2>", leaderboard(TABLE_COLUMNS + SWEEP_METRICS, table_rows(rows)), "</body></html>"]
    _atomic_text(os.path.join(folder, "sweep.html"), "\n".join(parts))


TABLE_COLUMNS = [("scene", "scene"), ("method", "method"), ("sweep values", "sweep_values"), ("seed", "seed")]


def table_rows(rows: list[dict]) -> list[dict]:
    """Sweep rows as the terminal table and the page's table show them: the method label as
    its method, the axis values as one text."""
    return [{"scene": r["scene"], "method": r["label"], "sweep_values": sweep_values(r["axes"]), "seed": r["seed"],
             **{key: r.get(key) for _, key in SWEEP_METRICS}} for r in rows]


def over_seeds(rows: list[dict]) -> list[dict]:
    """One entry per (scene, method label, axis values): the number of seeds and each of
    :data:`SWEEP_METRICS` as (mean, sample standard deviation) over the seeds that hold it,
    or the one value where one seed does."""
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["scene"], r["label"], _key(r["axes"])), []).append(r)
    out = []
    for (scene, label, _), members in groups.items():
        entry = {"scene": scene, "method": label, "sweep_values": sweep_values(members[0]["axes"]),
                 "seeds": len({m["seed"] for m in members})}
        for _, key in SWEEP_METRICS:
            values = [float(m[key]) for m in members if isinstance(m.get(key), (int, float)) and m[key] == m[key]]
            if values:
                entry[key] = (float(np.mean(values)), float(np.std(values, ddof=1))) if len(values) > 1 else values[0]
        out.append(entry)
    return out


def _atomic_text(path: str, text: str) -> None:
    tmp = f"{path}.tmp-{os.getpid()}"
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, path)
