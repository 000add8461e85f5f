"""Benchmark sweeps: suite expansion, job identity, resume without repeated work, and the
same sweep serially, on a spawned pool and on a loopback Dask LocalCluster."""
import contextlib
import io
import json
import os
import shutil

import pytest

from estimator import backend
from estimator.core.errors import InputError
from harness.cli.main import main
from harness.scene.spec import SpecError
from harness.sweep import jobs
from harness.sweep.executor import run_jobs, worker_threads
from harness.sweep.runner import plan
from harness.sweep.suite import load_suite


def _suite_file(tmp_path, text):
    path = tmp_path / "suite.toml"
    path.write_text(text)
    return str(path)


def test_suite_expands_axes_seeds_and_methods(tmp_path):
    path = _suite_file(tmp_path, """
name = "t"
profile = "tiny"
seeds = [0, 1]
methods = ["median-color", { method = "bilinear-clustered", label = "o4", params = { sh_order = 4 } }]
[[scenes]]
scene = "sparse-colored"
sweep = { "cameras.count" = [6, 12], "faults.noise_read" = [0.0, 0.1] }
""")
    suite = load_suite(path)
    assert len(suite["datasets"]) == 2 * 2 * 2 and [m.label for m in suite["methods"]] == ["median-color", "o4"]
    datasets, runs = plan(suite, str(tmp_path / "out"))
    assert len({d["id"] for d in datasets}) == 8 and len(runs) == 16
    assert len({r["id"] for r in runs}) == 16
    again, _ = plan(load_suite(path), str(tmp_path / "out"))
    assert [d["id"] for d in again] == [d["id"] for d in datasets]      # identity is deterministic
    _, bare = plan(suite, str(tmp_path / "out"), figures=False)         # figures change no metric: same runs
    assert [r["id"] for r in bare] == [r["id"] for r in runs] and not any(r["figures"] for r in bare)


def test_a_run_reported_without_figures_is_not_reused_when_figures_are_asked(tmp_path):
    (tmp_path / "report").mkdir()
    (tmp_path / "report" / "metrics.json").write_text("{}")
    for figures in (False, True):
        (tmp_path / jobs.JOB_FILE).write_text(json.dumps({"id": "x", "kind": "run", "metrics": {}, "figures": figures}))
        assert jobs.finished(str(tmp_path), "x", figures=False) is not None     # either serves a sweep without
        assert (jobs.finished(str(tmp_path), "x", figures=True) is not None) == figures


@pytest.mark.parametrize("text, needle", [
    ('methods = ["nope"]\nscenes = ["sparse-colored"]', "not a registered method"),
    ('methods = ["median-color"]\nscenes = ["sparse-colored"]\ncolour = 1', "unknown suite key"),
    ('methods = ["median-color"]\n[[scenes]]\nscene = "sparse-colored"\nsweep = { "cameras.count" = [] }',
     "non-empty lists"),
    ('methods = ["median-color"]\n[[scenes]]\nscene = "sparse-colored"\nsweep = { "cameras.count" = [0] }',
     "cameras.count"),
    ('methods = [{ method = "median-color", params = { sh_order = -1 } }]\nscenes = ["sparse-colored"]', "sh_order"),
    ('methods = ["median-color", "median-color"]\nscenes = ["sparse-colored"]', "labels must be distinct"),
    ('methods = [{ method = "median-color", label = " " }]\nscenes = ["sparse-colored"]',
     "label must be a non-empty string"),
    ('methods = ["median-color"]\n[[scenes]]\nscene = "sparse-colored"\nsweep = { "render.spp" = [1, 2] }\n'
     'set = { "render.spp" = 4 }', "render.spp both swept and set"),
])
def test_bad_suites_name_the_problem(tmp_path, text, needle):
    with pytest.raises(SpecError, match=needle):
        load_suite(_suite_file(tmp_path, text))


@pytest.mark.parametrize("text, needle", [
    ('methods = ["median-color"]\nscenes = ["sparse-colored", "nope"]', r"suite\.toml: scenes\[1\]: no scene spec"),
    ('methods = ["median-color"]\n[[scenes]]\nscene = "sparse-colored"\nsweep = { "cameras.count" = [6, -3] }',
     r"suite\.toml: scenes\[0\]: \{'cameras\.count': -3\}: cameras\.count must be >= 1"),
    ('methods = ["median-color"]\n[[scenes]]\nscene = "sparse-colored"\nset = { "cameras.bogus" = 3 }',
     r"suite\.toml: scenes\[0\]: its scene: unknown key cameras\.bogus"),
])
def test_a_bad_scene_entry_names_the_suite_file_and_the_entry(tmp_path, text, needle):
    with pytest.raises(SpecError, match=needle):
        load_suite(_suite_file(tmp_path, text))


def test_identity_changes_with_the_code_version(monkeypatch):
    a = jobs.identity({"x": 1})
    monkeypatch.setattr(jobs, "code_version", lambda: "other")
    assert jobs.identity({"x": 1}) != a


def test_worker_threads_split_the_cores():
    assert worker_threads(2, cores=2) == 1 and worker_threads(1, cores=8) == 8 and worker_threads(16, cores=2) == 1


def _square(job):
    if job["x"] < 0:
        raise ValueError("negative")
    return {"y": job["x"] ** 2}


def test_pool_runs_jobs_and_reports_failures_per_job():
    results = dict((j["x"], r) for j, r in run_jobs(_square, [{"x": 2}, {"x": -1}, {"x": 3}], "local", 2))
    assert results[2] == {"y": 4} and results[3] == {"y": 9} and isinstance(results[-1], ValueError)


def _environment(job):
    import os

    return {key: os.environ.get(key) for key in ("TQDM_DISABLE", "OMP_NUM_THREADS")}


def test_pool_workers_draw_no_progress_bars_and_share_the_cores():
    import os

    before = os.environ.get("TQDM_DISABLE")
    results = [r for _, r in run_jobs(_environment, [{"x": i} for i in range(2)], "local", 2)]
    assert all(r["TQDM_DISABLE"] == "1" and r["OMP_NUM_THREADS"] == str(worker_threads(2)) for r in results)
    assert os.environ.get("TQDM_DISABLE") == before            # the sweep's own environment is restored


def _device(job):
    import os
    import time

    time.sleep(0.3)   # long enough for every worker to take a job
    return {"device": os.environ.get("CUDA_VISIBLE_DEVICES"), "pid": os.getpid()}


def test_gpu_pool_pins_one_worker_per_device():
    # no GPU here: the pinning itself is what is tested (the CUDA variant passes gpus > 0)
    results = [r for _, r in run_jobs(_device, [{"x": i} for i in range(6)], "local", 4, gpus=2)]
    pids = {r["pid"] for r in results}
    assert len(pids) == 2                                      # one worker per GPU, not --jobs 4
    assert {r["device"] for r in results} == {"0", "1"}
    assert all(len({r["device"] for r in results if r["pid"] == p}) == 1 for p in pids)


SMOKE = ["bench", "smoke", "--no-mitsuba", "--no-figures"]   # the reports' figures are tested in tests/reports


@pytest.fixture(scope="module")
def smoke_sweep(tmp_path_factory):
    """The smoke sweep run once, serially, for this module: (its folder, what it printed).
    A test that changes the folder works on a copy."""
    out = tmp_path_factory.mktemp("sweep") / "smoke"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main([*SMOKE, "-o", str(out), "--dry-run"]) == 0
        dry = printed.getvalue()
        assert not out.exists()
        assert main([*SMOKE, "-o", str(out)]) == 0
    return out, dry, printed.getvalue()[len(dry):]


def test_smoke_sweep_runs_then_resumes_with_no_repeated_work(smoke_sweep, tmp_path, capsys):
    made, dry, first = smoke_sweep
    assert "2 datasets x 2 methods = 4 runs" in dry and "runs: 0 cached, 4 to run" in dry
    assert "2 datasets, 4 runs: 6 jobs run, 0 reused" in first
    out = tmp_path / "smoke"
    shutil.copytree(made, out)
    # the terminal table shows the sweep's own columns, each filled for these methods
    header, *lines = [line for line in first.splitlines() if line.startswith(("scene ", "sparse-colored "))]
    assert "diffuse PSNR, lstsq (dB)" in header and "sweep values" in header and len(lines) == 4
    assert all(line.split().count("-") == 1 for line in lines)   # only the seed, which smoke does not draw
    rows = json.load(open(out / "compare" / "sweep.json"))["rows"]
    assert {r["label"] for r in rows} == {"bilinear-clustered", "median-color"}
    assert {r["axes"]["cameras.count"] for r in rows} == {6, 12}
    html = (out / "compare" / "sweep.html").read_text()
    assert html.count("<img") == 1 and "cameras.count" in html
    assert "Over seeds" in html and "onclick='sortBy(this)'" in html and "class='best'" in html
    # the comparison's rows name each run's place in the sweep: its axis values and seed
    compared = json.load(open(out / "compare" / "compare.json"))["rows"]
    expected = {("cameras.count=6", None), ("cameras.count=12", None)}   # smoke draws no seeds
    assert {(r["sweep_values"], r["seed"]) for r in compared} == expected
    assert "cameras.count=12" in (out / "compare" / "compare.html").read_text()
    report = next((out / "runs").glob("*/report"))                        # --no-figures: metrics and page only
    assert (report / "metrics.json").is_file() and not list(report.glob("*.png"))
    assert "Figures not drawn" in (report / "report.html").read_text()
    # resumed: nothing is run again; the runs' files are untouched
    run_json = next((out / "runs").glob("*/run/run.json"))
    stamp = os.path.getmtime(run_json)
    assert main([*SMOKE, "-o", str(out)]) == 0
    assert "0 jobs run, 6 reused" in capsys.readouterr().out and os.path.getmtime(run_json) == stamp
    assert main([*SMOKE, "-o", str(out), "--dry-run"]) == 0
    assert "runs: 4 cached, 0 to run" in capsys.readouterr().out
    # an interrupted sweep: one run lost its record; only that job runs again
    os.remove(run_json.parent.parent / jobs.JOB_FILE)
    assert main([*SMOKE, "-o", str(out)]) == 0
    assert "1 jobs run, 5 reused" in capsys.readouterr().out
    # a damaged cached dataset (a truncated image) is made again, not reused for ever
    image = next((out / "datasets").glob("*/images/train_001.exr"))
    image.write_bytes(image.read_bytes()[:100])
    assert main([*SMOKE, "-o", str(out)]) == 0
    assert "1 jobs run, 5 reused" in capsys.readouterr().out and image.stat().st_size > 100
    # a regression verdict against a previous sweep: the same code passes; a baseline that
    # claims a better result than now (beyond the tolerance) fails, named per row and metric
    baseline = tmp_path / "baseline.json"
    baseline.write_text((out / "compare" / "sweep.json").read_text())
    assert main([*SMOKE, "-o", str(out), "--baseline", str(baseline)]) == 0
    assert "baseline sweep: 28 of 28 tracked metrics within tolerance" in capsys.readouterr().out   # 4 rows x 7
    verdict = json.load(open(out / "compare" / "regression.json"))
    assert verdict["worse"] == 0 and verdict["compared"] >= 4
    better = json.loads(baseline.read_text())
    better["rows"][0]["albedo.diffuse.lstsq.luminance.within_10"] = 1.5
    baseline.write_text(json.dumps(better))
    assert main([*SMOKE, "-o", str(out), "--baseline", str(baseline)]) == 1
    err = capsys.readouterr().err
    assert err.count("REGRESSION") == 1 and "albedo.diffuse.lstsq.luminance.within_10" in err
    assert "Regression against the baseline sweep" in (out / "compare" / "sweep.html").read_text()
    baseline.write_text("{}")
    assert main([*SMOKE, "-o", str(out), "--baseline", str(baseline)]) == 2
    assert "a sweep.json holds 'rows'" in capsys.readouterr().err


def test_smoke_sweep_on_a_spawned_pool_and_on_dask_matches_the_serial_one(smoke_sweep, tmp_path, capsys):
    distributed = pytest.importorskip("dask.distributed")
    pool = tmp_path / "pool"
    assert main([*SMOKE, "-o", str(pool), "--jobs", "2"]) == 0
    assert "6 jobs run" in capsys.readouterr().out
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        out = tmp_path / "dask"
        assert main([*SMOKE, "-o", str(out), "--executor", "dask", "--scheduler", cluster.scheduler_address]) == 0
    assert "6 jobs run" in capsys.readouterr().out
    key = "albedo.diffuse.lstsq.luminance.within_10"
    serial, *others = (sorted((r["label"], r["axes"]["cameras.count"], r[key])
                              for r in json.load(open(folder / "compare" / "sweep.json"))["rows"])
                       for folder in (smoke_sweep[0], pool, out))
    assert all(rows == serial for rows in others)


@pytest.mark.parametrize("text, needle", [
    ('methods = [{ method = "median-color", label = "a b" }, { method = "bilinear-per-face", label = "a/b" }]\n'
     'scenes = ["sparse-colored"]', "map to the same run folder"),
    ('methods = ["median-color"]\nscenes = [{ scene = ["sparse-colored"] }]', "scene must be a scene name"),
    ('name = 5\nmethods = ["median-color"]\nscenes = ["sparse-colored"]', "suite.name must be a string"),
    ('methods = [{ method = "median-color", params = { foo = 1 } }]\nscenes = ["sparse-colored"]',
     "unknown estimator parameter(s) foo"),
    ('seeds = [1, 1]\nmethods = ["median-color"]\nscenes = ["sparse-colored"]', "seeds must be distinct"),
])
def test_more_bad_suites(tmp_path, text, needle):
    with pytest.raises((SpecError, InputError), match=needle.replace("(", r"\(").replace(")", r"\)")):
        plan(load_suite(_suite_file(tmp_path, text)), str(tmp_path / "out"))


def test_nested_set_tables_merge_into_the_spec(tmp_path):
    suite = load_suite(_suite_file(tmp_path, 'profile = "tiny"\nmethods = ["median-color"]\n'
                                              '[[scenes]]\nscene = "sparse-colored"\nset = { cameras.count = 5 }'))
    from harness.scene.spec import load_spec

    d = suite["datasets"][0]
    spec = load_spec(d.spec_path, d.profile, d.overrides)
    assert spec.cameras.count == 5 and spec.cameras.width == 96      # the tiny profile's width is kept


@pytest.fixture
def silent_listener():
    """A loopback port that accepts connections and never says a word (as the dashboard's or
    any non-Dask service's port would to a Dask client)."""
    import socket
    import threading

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    accepted = []
    stop = threading.Event()

    def accept():
        server.settimeout(0.1)
        while not stop.is_set():
            try:
                accepted.append(server.accept()[0])
            except OSError:
                continue

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    stop.set()
    thread.join()
    for conn in accepted:
        conn.close()
    server.close()


def test_a_port_that_does_not_speak_dask_is_refused_not_waited_on(silent_listener, tmp_path, capsys):
    from harness.sweep import executor

    with pytest.raises(InputError, match="no Dask handshake"):
        executor.probe_scheduler(silent_listener, timeout=0.3)
    assert main(["bench", "smoke", "-o", str(tmp_path / "b"), "--executor", "dask",
                 "--scheduler", silent_listener]) == 2
    err = capsys.readouterr().err
    assert "no Dask handshake" in err and "Traceback" not in err
    assert not (tmp_path / "b").exists()


def test_a_sweep_folder_is_claimed_by_its_suite_and_released_when_nothing_finished(tmp_path):
    """The marker names the suite: the same suite may resume in its folder, another is refused
    (it would replace the first's comparison); a first run stopped before any job finished
    (empty folders at most) leaves no folder, a folder that holds a job's file is kept, and a
    folder the user made is not counted as made by the sweep."""
    from harness.io.atomic import OutputError
    from harness.sweep.runner import SWEEP_MARKER, claim_sweep_folder, release_sweep_folder

    out = tmp_path / "sweep"
    assert claim_sweep_folder(str(out), "first") is True
    assert claim_sweep_folder(str(out), "first") is False                 # resumed
    with pytest.raises(OutputError, match="holds the sweep of suite 'first'"):
        claim_sweep_folder(str(out), "second")
    (out / "datasets").mkdir()             # what an interrupted first job leaves: an empty folder
    release_sweep_folder(str(out))
    assert not out.exists()
    claim_sweep_folder(str(out), "first")
    (out / "datasets" / "job").mkdir(parents=True)
    (out / "datasets" / "job" / "job.json").write_text("{}")
    release_sweep_folder(str(out))
    assert sorted(p.name for p in out.iterdir()) == [SWEEP_MARKER, "datasets"]
    empty = tmp_path / "empty"
    empty.mkdir()                          # the user's own empty folder is not removed
    assert claim_sweep_folder(str(empty), "first") is False


def test_bench_never_writes_into_a_folder_of_the_users(tmp_path, capsys):
    user = tmp_path / "mine"
    user.mkdir()
    (user / "sweep-summary.json").write_text("my notes")
    assert main(["bench", "smoke", "-o", str(user), "--profile", "tiny"]) == 2
    assert "not made by pseudolight bench" in capsys.readouterr().err
    assert (user / "sweep-summary.json").read_text() == "my notes" and len(list(user.iterdir())) == 1


def test_version_and_each_commands_own_usage_line(capsys):
    assert main(["--version"]) == 0 and capsys.readouterr().out.startswith("pseudolight ")
    for name in ("bench", "suite"):
        assert main([name, "--help"]) == 0
        assert capsys.readouterr().out.startswith(f"usage: pseudolight {name} ")


def _park(job):
    """A job that records its worker's pid, then waits far longer than any test."""
    import os
    import time

    with open(os.path.join(job["folder"], f"{os.getpid()}.pid"), "w"):
        pass
    time.sleep(600)
    return {}


POOL_PARENT = """
import signal, sys
from harness.sweep.executor import run_jobs
signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))   # as the CLI: unwind (a BaseException)
from tests.harness.test_sweep import _park
list(run_jobs(_park, [{"folder": sys.argv[1], "x": i} for i in range(4)], "local", 2))
"""


def _alive(pid: int) -> bool:
    import os

    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:                  # a zombie has ended too
        return f.read().split(") ", 1)[1][0] != "Z"


@pytest.mark.parametrize("how", ["SIGKILL", "SIGTERM"])
def test_pool_workers_end_with_their_sweep(tmp_path, how):
    """A killed sweep left its workers waiting forever (SIGKILL), or waited for every queued
    job before exiting (SIGTERM: here for ever). Liveness is polled with a generous bound,
    not timed."""
    import os
    import signal
    import subprocess
    import sys
    import time

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    parent = subprocess.Popen([sys.executable, "-c", POOL_PARENT, str(tmp_path)], cwd=root,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while len(list(tmp_path.glob("*.pid"))) < 2 and time.monotonic() < deadline:
        time.sleep(0.1)
    workers = [int(p.stem) for p in tmp_path.glob("*.pid")]
    assert len(workers) == 2
    parent.send_signal(getattr(signal, how))
    parent.wait(timeout=120)
    while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(_alive(pid) for pid in workers)


@pytest.mark.skipif(backend.cuda_device_count() > 0, reason="this machine has a CUDA GPU")
def test_a_cuda_sweep_without_a_gpu_fails_once_before_writing(tmp_path, capsys):
    out = tmp_path / "sweep"
    assert main(["bench", "smoke", "-o", str(out), "--no-mitsuba", "--variant", "cuda_ad_rgb"]) == 2
    err = capsys.readouterr().err
    assert "no usable CUDA GPU" in err and "FAILED" not in err and not out.exists()
