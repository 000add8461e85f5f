"""Self-contained HTML pages (figures embedded as data URIs) and terminal summaries."""
from __future__ import annotations

import base64
import html
import json

SUMMARY_ROWS = [  # (label, dotted path, format)
    ("pseudo illumination: SH relative L2", "illumination.relative_l2", "{:.4f}"),
    ("specular albedo within ±10 % (DC gauge)", "albedo.specular.dc.luminance.within_10", "{:.3f}"),
    ("specular albedo within ±5 % (DC gauge)", "albedo.specular.dc.luminance.within_5", "{:.3f}"),
    ("specular median ratio (DC gauge)", "albedo.specular.dc.luminance.median_ratio", "{:.3f}"),
    ("specular within ±10 % (least-squares scale)", "albedo.specular.lstsq.luminance.within_10", "{:.3f}"),
    ("specular CIEDE2000 median", "albedo.specular.ciede2000.median", "{:.2f}"),
    ("diffuse albedo within ±10 % (DC gauge)", "albedo.diffuse.dc.luminance.within_10", "{:.3f}"),
    ("diffuse median ratio (DC gauge)", "albedo.diffuse.dc.luminance.median_ratio", "{:.3f}"),
    ("diffuse within ±10 % (least-squares scale)", "albedo.diffuse.lstsq.luminance.within_10", "{:.3f}"),
    ("diffuse albedo PSNR, least-squares scale (dB)", "albedo.diffuse.psnr_lstsq", "{:.2f}"),
    ("diffuse CIEDE2000 median", "albedo.diffuse.ciede2000.median", "{:.2f}"),
    ("clusters: adjusted Rand index", "clusters.ari", "{:.3f}"),
    ("clusters found", "clusters.clusters", "{}"),
    ("novel views: PSNR sRGB (dB)", "novel_views.psnr_srgb", "{:.2f}"),
    ("novel views: SSIM sRGB", "novel_views.ssim_srgb", "{:.4f}"),
    ("novel views: PSNR linear (dB)", "novel_views.psnr_linear", "{:.2f}"),
    ("novel views: object pixels not estimated", "novel_views.unestimated_pixel_share", "{:.3f}"),
    ("relighting: PSNR sRGB (dB)", "relighting.psnr_srgb", "{:.2f}"),
    ("relighting: SSIM sRGB", "relighting.ssim_srgb", "{:.4f}"),
    ("Mitsuba re-render vs forward model: relative L2", "mitsuba_cross_check.relative_l2", "{:.4f}"),
    ("faces evaluated (specular / diffuse)", None, None),
    ("self-check: median relative residual", "self_check.residual.median_relative", "{:.4f}"),
    ("self-check: observations outside 3 robust scales", "self_check.outlier_share", "{:.3f}"),
    ("self-check: light condition number", "self_check.light_condition", "{:.3g}"),
    ("self-check: albedo relative standard error (median)", "self_check.albedo_relative_se.median", "{:.4f}"),
    ("self-check: cross-validated prediction PSNR (dB)", "self_check.cross_validation_psnr", "{:.2f}"),
]


NOISE_NOTE = " (the render's own Monte Carlo noise taken out)"


def lookup(metrics: dict, path: str):
    """Value at a dotted path, or None when any part is missing."""
    node = metrics
    for key in path.split("."):
        if not isinstance(node, dict) or node.get(key) is None:
            return None
        node = node[key]
    return node


def summary_rows(metrics: dict) -> list[tuple[str, str]]:
    rows = []
    for label, path, fmt in SUMMARY_ROWS:
        if path is None:
            spec = lookup(metrics, "albedo.specular.evaluated_faces")
            dif = lookup(metrics, "albedo.diffuse.evaluated_faces")
            rows.append((label, f"{spec if spec is not None else '-'} / {dif if dif is not None else '-'}"))
            continue
        value = lookup(metrics, path)
        if value is not None:
            arrow = {"up": " ↑", "down": " ↓"}.get(direction(path), "")
            rows.append((label + arrow, fmt.format(value)))
    return rows


def terminal_summary(metrics: dict) -> str:
    rows = summary_rows(metrics)
    width = max(len(label) for label, _ in rows)
    head = f"{metrics.get('scene', '?')} / {metrics.get('method', '?')}"
    return "\n".join([head, "-" * len(head)] + [f"{label:<{width}}  {value}" for label, value in rows])


def embed_png(png: bytes, alt: str) -> str:
    """An <img> tag holding the PNG as a data URI."""
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{base64.b64encode(png).decode()}">'


STYLE = """body{font-family:system-ui,sans-serif;margin:2em;max-width:1400px;color:#222}
table{border-collapse:collapse;margin:1em 0;font-size:13px}td,th{border:1px solid #ccc;padding:4px 8px;text-align:left}
th{background:#f0f0f0}img{max-width:100%;margin:0.5em 0}h2{margin-top:1.6em}.wide{overflow-x:auto}
table.lb th{cursor:pointer;white-space:nowrap}table.lb td.best{background:#d6f0d6;font-weight:600}
.ok{color:#176617}.bad{color:#a11}pre{background:#f6f6f6;padding:1em;overflow:auto;font-size:12px}
.note{color:#555;font-size:13px}"""

# sorts a leaderboard by the clicked column: numbers (data-v) before text, again to reverse
SORT_SCRIPT = """<script>
function sortBy(th){
 const body=th.closest('table').tBodies[0],i=th.cellIndex,asc=th.dataset.asc!=='1';
 th.dataset.asc=asc?'1':'0';
 const key=r=>{const c=r.cells[i];return c.dataset.v!==undefined?parseFloat(c.dataset.v):c.textContent;};
 const rows=[...body.rows];
 rows.sort((a,b)=>{const x=key(a),y=key(b);
  if(typeof x==='number'&&typeof y==='number')return asc?x-y:y-x;
  if(typeof x==='number')return -1;if(typeof y==='number')return 1;
  return asc?String(x).localeCompare(y):String(y).localeCompare(x);});
 rows.forEach(r=>body.appendChild(r));}
</script>"""

LEADERBOARD_NOTE = ("<p class='note'>↑ higher is better, ↓ lower is better; the best value of each such column is "
                    "highlighted; click a column's header to sort by it.</p>")


def direction(key: str) -> str | None:
    """'up' where a higher value of the metric ``key`` (a dotted path) is better, 'down' where
    lower is, None where neither (a count, a ratio whose best is 1, a name)."""
    leaf = key.lower().split(".")[-1]
    if leaf == "ari" or leaf.startswith(("within_", "psnr", "ssim")):
        return "up"
    if any(part in key.lower() for part in ("relative_l2", "abs_error", "seconds", "ciede", "flip", "lpips")):
        return "down"
    return None


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and value == value


def leaderboard(columns: list[tuple[str, str]], rows: list[dict]) -> str:
    """A sortable table (the page must hold :data:`SORT_SCRIPT`): columns (label, key), a
    row per dict; a value is a number, text, or a (mean, spread) pair shown as 'mean ± spread'
    and sorted by its mean. Each header carries its metric's direction (:func:`direction`),
    and the best value of each directed column with two or more numbers is highlighted."""
    def mean(v):
        return v[0] if isinstance(v, tuple) else v

    dirs = [direction(key) for _, key in columns]
    best = {}
    for (_, key), d in zip(columns, dirs):
        values = [mean(r.get(key)) for r in rows if _number(mean(r.get(key)))]
        if d and len(values) > 1 and max(values) > min(values):   # a tie of every row marks nothing
            best[key] = max(values) if d == "up" else min(values)
    head = "".join(f"<th onclick='sortBy(this)' title='click to sort'>{html.escape(label)}"
                   f"{' ↑' if d == 'up' else ' ↓' if d == 'down' else ''}</th>" for (label, _), d in zip(columns, dirs))
    body = []
    for row in rows:
        cells = []
        for _, key in columns:
            v = row.get(key)
            m = mean(v)
            if not _number(m):
                cells.append(f"<td>{'-' if v is None else html.escape(str(v))}</td>")
                continue
            shown = f"{m:.4g} ± {v[1]:.2g}" if isinstance(v, tuple) else f"{m:.4g}" if isinstance(m, float) else str(m)
            cls = " class='best'" if key in best and m == best[key] else ""
            cells.append(f"<td data-v='{m!r}'{cls}>{html.escape(shown)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return (f"<div class='wide'><table class='lb'><thead><tr>{head}</tr></thead><tbody>" + "\n".join(body)
            + "</tbody></table></div>")


def report_page(metrics: dict, figures: list[tuple[str, str, bytes]] | None,
                regressions: list[dict] | None = None) -> str:
    """One self-contained page: summary table, figures (section, caption, PNG bytes; None:
    the report was written without them, which the page says), raw metrics."""
    title = f"pseudolight report: {metrics.get('scene', '?')} / {metrics.get('method', '?')}"
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
             f"<style>{STYLE}</style></head><body><h1>{html.escape(title)}</h1>",
             f"<p>dataset <code>{html.escape(str(metrics.get('dataset')))}</code>, run "
             f"<code>{html.escape(str(metrics.get('run')))}</code></p>",
             "<p class='note'>↑ higher is better, ↓ lower is better.</p>",
             "<table><tr><th>metric</th><th>value</th></tr>"]
    parts += [f"<tr><td>{html.escape(k)}</td><td>{html.escape(v)}</td></tr>" for k, v in summary_rows(metrics)]
    parts.append("</table>")
    if metrics.get("ground_truth", True) is None:
        parts.append("<p>No ground truth: this is the self-check report (what the inputs alone say).</p>")
    warnings = (metrics.get("self_check") or {}).get("warnings") or []
    if warnings:
        parts.append("<p class='bad'>Warnings:</p><ul>" + "".join(f"<li>{html.escape(w)}</li>" for w in warnings)
                     + "</ul>")
    cc = metrics.get("mitsuba_cross_check") or {}
    if "pass" in cc:
        cls = "ok" if cc["pass"] else "bad"
        parts.append(f"<p class='{cls}'>Mitsuba cross-check {'passed' if cc['pass'] else 'FAILED'}: "
                     f"largest relative L2 per view over pixels covered by one face "
                     f"{max(v[cc.get('compared', 'relative_l2')] for v in cc['per_view']):.4f}"
                     f"{NOISE_NOTE if cc.get('compared') == 'relative_l2_noise_free' else ''}"
                     f" (tolerance {cc['tolerance']})</p>")
    if regressions is not None:
        worse = [r for r in regressions if r["status"] != "ok"]
        cls = "bad" if worse else "ok"
        parts.append(f"<h2>Regression against baseline</h2><p class='{cls}'>"
                     f"{len(worse)} of {len(regressions)} tracked metrics worse</p>" + regression_table(regressions))
    for key, label in (("novel_views", "Novel views"), ("relighting", "Relighting")):
        table = protocol_table((metrics.get(key) or {}).get("protocols") or {})
        if table:
            parts.append(f"<h2>{label}: published benchmarks' protocols</h2>{table}")
    if figures is None:
        parts.append("<p class='note'>Figures not drawn (the report was made with --no-figures).</p>")
    section = None
    for sec, caption, png in figures or []:
        if sec != section:
            parts.append(f"<h2>{html.escape(sec)}</h2>")
            section = sec
        parts.append(f"<figure>{embed_png(png, caption)}<figcaption>{html.escape(caption)}</figcaption></figure>")
    parts.append("<h2>All metrics</h2><pre>" + html.escape(json.dumps(metrics, indent=1)) + "</pre></body></html>")
    return "\n".join(parts)


def protocol_table(block: dict) -> str:
    """The protocols of one image set (:func:`reports.protocols.score`'s output) as one table:
    a row per protocol with its alignment and each metric's mean over the views (arrow: the
    better direction); a metric that could not be computed says why. '' when empty."""
    if not block:
        return ""
    out = ["<table><tr><th>protocol</th><th>alignment</th><th>metrics (mean over views)</th></tr>"]
    for name, entry in block.items():
        cells = []
        for key, higher in entry.get("higher_is_better", {}).items():
            value = entry.get(key)
            shown = "unavailable" if value is None else f"{value:.4g}"
            cells.append(f"{html.escape(key)} {'↑' if higher else '↓'} {shown}")
        notes = "".join(f"<br><small>{html.escape(r)}</small>" for r in entry.get("unavailable", []))
        out.append(f"<tr><td>{html.escape(name)}</td><td>{html.escape(entry.get('alignment', ''))}</td>"
                   f"<td>{' · '.join(cells)}{notes}</td></tr>")
    return "\n".join(out + ["</table>"])


def regression_table(rows: list[dict]) -> str:
    out = ["<table><tr><th>metric</th><th>baseline</th><th>now</th><th>tolerance</th><th>status</th></tr>"]
    for r in rows:
        cls = "ok" if r["status"] == "ok" else "bad"
        now = html.escape(r.get("note") or "missing") if r["current"] is None else f"{r['current']:.4g}"
        out.append(f"<tr><td>{html.escape(r['metric'])}</td><td>{r['baseline']:.4g}</td><td>{now}</td>"
                   f"<td>{r['direction']} is better, ±{r['tolerance']:g}</td><td class='{cls}'>{r['status']}</td></tr>")
    return "\n".join(out + ["</table>"])


def compare_page(rows: list[dict], columns: list[tuple[str, str]], figures: list[tuple[str, bytes]]) -> str:
    """compare.html: one sortable leaderboard (a row per run, named by its scene, method and,
    from a sweep, its sweep values and seed) and the overlaid histograms."""
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>pseudolight comparison</title>"
             f"<style>{STYLE}</style>{SORT_SCRIPT}</head><body><h1>pseudolight comparison</h1>",
             LEADERBOARD_NOTE, leaderboard(columns, rows)]
    for caption, png in figures:
        parts.append(f"<figure>{embed_png(png, caption)}<figcaption>{html.escape(caption)}</figcaption></figure>")
    return "\n".join(parts + ["</body></html>"])
