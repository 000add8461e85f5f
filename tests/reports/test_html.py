"""The leaderboard tables of compare.html and sweep.html: directions, the best value, sorting
hooks, mean ± spread."""
import re

from reports import html
from reports.sweep import over_seeds


def test_direction_of_metrics():
    assert html.direction("albedo.diffuse.lstsq.luminance.within_10") == "up"
    assert html.direction("albedo.diffuse.psnr_lstsq") == "up" and html.direction("clusters.ari") == "up"
    assert html.direction("novel_views.ssim_srgb") == "up"
    assert html.direction("illumination.relative_l2") == "down" and html.direction("seconds") == "down"
    assert html.direction("albedo.specular.dc.luminance.median_ratio") is None   # best at 1, not at an end
    assert html.direction("clusters.clusters") is None and html.direction("scene") is None


def test_leaderboard_marks_the_best_of_each_directed_column():
    rows = [{"method": "a", "psnr": 30.0, "seconds": 9.0, "count": 3},
            {"method": "b", "psnr": 35.5, "seconds": 20.0, "count": 5},
            {"method": "c", "psnr": None, "seconds": 4.5, "count": 4}]
    page = html.leaderboard([("method", "method"), ("PSNR", "psnr"), ("time", "seconds"), ("n", "count")], rows)
    assert "PSNR ↑" in page and "time ↓" in page and "n ↑" not in page and "n ↓" not in page
    best = re.findall(r"data-v='([^']*)' class='best'", page)
    assert best == ["35.5", "4.5"]                      # highest PSNR, shortest time, nothing for the count
    assert page.count("onclick='sortBy(this)'") == 4 and "<td>-</td>" in page
    tied = html.leaderboard([("PSNR", "psnr")], [{"psnr": 1.0}, {"psnr": 1.0}])
    assert "best" not in tied
    assert "function sortBy" in html.SORT_SCRIPT


def test_over_seeds_gives_mean_and_spread_per_setting():
    rows = [{"scene": "s", "label": "m", "axes": {"views": 6}, "seed": k, "seconds": t}
            for k, t in ((0, 1.0), (1, 3.0))] + [{"scene": "s", "label": "m", "axes": {"views": 12}, "seed": 0,
                                                  "seconds": 5.0}]
    groups = {g["sweep_values"]: g for g in over_seeds(rows)}
    assert groups["views=6"]["seeds"] == 2 and groups["views=6"]["seconds"] == (2.0, 2 ** 0.5)
    assert groups["views=12"]["seconds"] == 5.0   # one seed: no spread to show
    page = html.leaderboard([("time", "seconds")], list(groups.values()))
    assert "2 ± 1.4" in page and "data-v='2.0' class='best'" in page
