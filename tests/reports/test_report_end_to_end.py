"""The report, compare and regression commands on a tiny dataset."""
import json
import os
import re

import pytest

from harness.cli.main import main


@pytest.fixture(scope="module")
def tiny_report(tiny_earth, tmp_path_factory):
    root = tmp_path_factory.mktemp("report")
    run, report = root / "run", root / "report"
    assert main(["estimate", tiny_earth, "-o", str(run)]) == 0
    assert main(["report", str(run), "-o", str(report), "--cross-check-spp", "16",
                 "--write-baseline", str(root / "baseline.json")]) == 0
    return root


def test_report_contents(tiny_report):
    report = tiny_report / "report"
    m = json.load(open(report / "metrics.json"))
    assert m["schema"] == "pseudolight-metrics" and m["schema_version"] == 1
    assert m["scene"] == "earth-specular" and m["method"] == "bilinear-per-face"
    assert m["albedo"]["diffuse"] == {"present": False}
    spec = m["albedo"]["specular"]
    assert spec["evaluated_faces"] > 1000 and spec["dc"]["luminance"]["within_10"] > 0.85
    assert m["illumination"]["relative_l2"] < 0.05
    assert m["novel_views"]["views"] == 2 and m["novel_views"]["psnr_srgb"] > 25
    assert m["relighting"]["psnr_srgb"] > 20
    for key in ("novel_views", "relighting"):   # the published protocols, all by default
        block = m[key]["protocols"]
        assert list(block) == ["stanford-orb", "nerfactor", "tensoir", "raw"]
        assert block["stanford-orb"]["psnr_l"] > 20 and 0 < block["raw"]["flip_hdr"] < 1
        assert len(block["nerfactor"]["per_view"]) == m[key]["views"]
    cc = m["mitsuba_cross_check"]
    assert cc["pass"] and cc["compared"] == "relative_l2_noise_free"
    assert all(0 < v["render_noise"] and v["relative_l2_noise_free"] <= v["relative_l2"] < cc["tolerance"] + 0.05
               for v in cc["per_view"])
    assert os.path.isfile(report / "mitsuba" / "scene.xml")


def test_report_html_is_self_contained(tiny_report):
    page = open(tiny_report / "report" / "report.html").read()
    sources = re.findall(r'src="([^"]*)"', page)
    assert len(sources) >= 6 and all(s.startswith("data:image/png;base64,") for s in sources)
    assert "href=" not in page and "<script" not in page


def test_baseline_regression_exit_codes(tiny_report, capsys):
    base = tiny_report / "baseline.json"
    run = tiny_report / "run"
    assert main(["report", str(run), "-o", str(tiny_report / "again"), "--cross-check-spp", "16",
                 "--baseline", str(base)]) == 0
    # a metric the baseline tracks but the report lacks counts as a regression
    skip = tiny_report / "skip"
    assert main(["report", str(run), "-o", str(skip), "--no-mitsuba", "--no-figures", "--baseline", str(base)]) == 1
    err = capsys.readouterr().err
    # a tracked metric the report lacks is no typo: no suggestion
    assert "REGRESSION mitsuba_cross_check.relative_l2_noise_free: baseline" in err
    assert "now missing or not a finite number" in err and "did you mean" not in err
    # --no-figures: the same metrics, no PNG, and a page that says so
    full, bare = (json.load(open(folder / "metrics.json")) for folder in (tiny_report / "report", skip))
    assert bare["albedo"] == full["albedo"] and bare["novel_views"]["psnr_srgb"] == full["novel_views"]["psnr_srgb"]
    assert not list(skip.glob("*.png")) and "Figures not drawn" in (skip / "report.html").read_text()
    worse = json.load(open(base))
    worse["metrics"]["albedo.specular.dc.luminance.within_10"] = 1.5  # impossible to reach
    worse["metrics"].pop("mitsuba_cross_check.relative_l2_noise_free", None)
    worse["metrics"]["albedo.diffuse.psnr_lstq"] = 10.0   # a typo in a hand-written baseline
    json.dump(worse, open(tiny_report / "worse.json", "w"))
    capsys.readouterr()
    assert main(["report", str(run), "-o", str(tiny_report / "third"), "--no-mitsuba", "--protocol", "raw",
                 "--baseline", str(tiny_report / "worse.json")]) == 1
    err = capsys.readouterr().err
    assert "REGRESSION albedo.specular.dc.luminance.within_10" in err
    assert ("REGRESSION albedo.diffuse.psnr_lstq: baseline 10, now not a metric of this report; "
            "did you mean 'albedo.diffuse.psnr_lstsq'?") in err
    third = json.load(open(tiny_report / "third" / "metrics.json"))
    assert list(third["novel_views"]["protocols"]) == ["raw"]


def test_compare_two_reports(tiny_report, tiny_earth):
    other = tiny_report / "median"
    assert main(["estimate", tiny_earth, "-o", str(other / "run"), "--method", "median-color"]) == 0
    assert main(["report", str(other / "run"), "-o", str(other / "report"), "--no-mitsuba"]) == 0
    out = tiny_report / "cmp"
    assert main(["compare", str(tiny_report / "report"), str(other), "-o", str(out)]) == 0
    table = json.load(open(out / "compare.json"))
    methods = [r["method"] for r in table["rows"]]
    assert methods == ["bilinear-per-face", "median-color"]
    good, naive = table["rows"]
    assert good["albedo.specular.dc.luminance.within_10"] > naive["albedo.specular.dc.luminance.within_10"]
    assert "data:image/png;base64," in open(out / "compare.html").read()
    assert main(["compare", str(tiny_report / "nothing"), "-o", str(tiny_report / "cmp2")]) == 2
