"""The estimate runs its dense linear algebra on ``blas_threads`` BLAS threads (one by default) and
gives the caller's back."""
import numpy as np
from threadpoolctl import threadpool_info, threadpool_limits

import estimator.api as api
from estimator import estimate
from estimator.core.blas import limited_blas

from .micro import micro_config, micro_scene


def blas_threads() -> list[int]:
    return [info["num_threads"] for info in threadpool_info() if info["user_api"] == "blas"]


def test_one_blas_thread_inside_and_the_callers_limit_after():
    seen = []

    def work(x):
        with limited_blas(1):
            seen.extend(blas_threads())
            return x @ x.T

    with threadpool_limits(limits=2, user_api="blas"):
        before = blas_threads()
        out = work(np.eye(3))
        assert blas_threads() == before
    assert seen and set(seen) == {1}
    np.testing.assert_array_equal(out, np.eye(3))


def test_the_estimate_solves_on_one_blas_thread(monkeypatch):
    """The method's solve (inside :func:`estimate`) sees one BLAS thread."""
    seen = []
    solve = api._solve

    def spy(*args, **kwargs):
        seen.extend(blas_threads())
        return solve(*args, **kwargs)

    monkeypatch.setattr(api, "_solve", spy)
    data, _ = micro_scene()
    with threadpool_limits(limits=2, user_api="blas"):
        estimate(data, "retinex-segmented", micro_config())
    assert seen and set(seen) == {1}


def test_overlapping_limited_calls_share_one_limit_and_restore_it_once(monkeypatch):
    """Two limited calls in two threads, the first returning while the second runs: one limit
    is set (when the first enters) and restored once (when the last leaves), so the second does
    not lose it midway and the process does not keep it after."""
    import threading

    import estimator.core.blas as blas

    made = []
    real = blas.threadpool_limits

    def counted(*args, **kwargs):
        made.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(blas, "threadpool_limits", counted)
    first_done, second_started = threading.Event(), threading.Event()
    depth = {}

    def first():
        with limited_blas(1):
            second_started.wait(10)

    def second():
        with limited_blas(1):
            second_started.set()
            first_done.wait(10)
            depth["second"] = blas._held["depth"]

    with threadpool_limits(limits=2, user_api="blas"):
        before = blas_threads()
        a, b = threading.Thread(target=first), threading.Thread(target=second)
        a.start(), b.start()
        a.join()
        first_done.set()
        b.join()
        assert made == [1] and depth["second"] == 1      # the first's exit left the limit in place
        assert blas._held == {"depth": 0, "limits": None} and blas_threads() == before


def test_blas_threads_sets_the_count_and_zero_leaves_the_process_setting(monkeypatch):
    """``blas_threads`` = 2 gives the solve two threads; 0 leaves the caller's limit as it is."""
    seen = []
    solve = api._solve

    def spy(*args, **kwargs):
        seen.append(set(blas_threads()))
        return solve(*args, **kwargs)

    monkeypatch.setattr(api, "_solve", spy)
    data, _ = micro_scene()
    with threadpool_limits(limits=3, user_api="blas"):
        estimate(data, "retinex-segmented", micro_config(blas_threads=2))
        estimate(data, "retinex-segmented", micro_config(blas_threads=0))
    assert seen == [{2}, {3}]
