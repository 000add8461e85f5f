"""The comparison's error-against-time figure: a point per run, a curve for a method that
records its albedo over time."""
from reports.report import compare_figures, error_against_time


def _metrics(method, seconds, psnr, history=None):
    diffuse = {"present": True, "psnr_lstsq": psnr}
    if history:
        diffuse["psnr_history"] = {"seconds": [t for t, _ in history], "psnr_lstsq": [p for _, p in history]}
    return {"scene": "s", "method": method, "estimate_timings": {"total": seconds}, "albedo": {"diffuse": diffuse}}


def test_error_against_time_reads_time_psnr_and_curve():
    run = error_against_time(_metrics("mitsuba-ad", 60.0, 25.0, [(5.0, 12.0), (30.0, 20.0), (60.0, None)]))
    assert run == {"method": "mitsuba-ad", "seconds": 60.0, "psnr": 25.0, "curve": [(5.0, 12.0), (30.0, 20.0)]}
    assert error_against_time({"method": "m", "albedo": {"diffuse": {"psnr_lstsq": 20.0}}}) is None   # no time
    assert error_against_time(_metrics("m", 3.0, None)) is None                                      # no diffuse


def test_compare_figures_add_one_time_plot_per_scene():
    figs = compare_figures([(_metrics("retinex-segmented", 6.0, 33.0), {}),
                            (_metrics("mitsuba-ad", 60.0, 25.0, [(5.0, 12.0), (60.0, 25.0)]), {})])
    assert [title for title, _ in figs] == ["s: diffuse albedo PSNR against estimate time"]
    assert figs[0][1][:8] == b"\x89PNG\r\n\x1a\n"


def test_run_labels_tell_sweep_runs_of_one_method_apart():
    from reports.report import run_label

    a = {"method": "bilinear-clustered", "sweep_values": "cameras.count=6", "seed": 1}
    b = {"method": "bilinear-clustered", "sweep_values": "cameras.count=12", "seed": None}
    assert run_label(a) == "bilinear-clustered · cameras.count=6 · seed 1"
    assert run_label(b) == "bilinear-clustered · cameras.count=12"
    assert run_label({"method": "median-color", "sweep_values": None, "seed": None}) == "median-color"
