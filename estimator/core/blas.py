"""How many threads the estimator's dense linear algebra runs on: one, for a whole estimate.

Its BLAS products are many and small: each Gauss-Newton step of the edge fit forms a (k, F) x
(F, k) product (k = 24 light coefficients, F = 5k faces: about 1.4 ms), the trust diagnostics'
Gram matrices are (M, M). At that size a second OpenBLAS thread costs about what it saves, and
when other work shares the cores its threads wait on each other: on the 2-core development
machine, with one other process running, the default method's estimate of a 5k-face real-light
scene took 28.6 s with OpenBLAS's two threads and 5.6 s with one (the edge fit's product 18 ms a
call); alone on the machine the two took the same time. :func:`one_blas_thread` limits BLAS
through ``threadpoolctl`` (which finds the BLAS library numpy and scipy loaded, whichever it is)
and restores the caller's setting after. The limit is the process's: estimates running in
several threads at once (a Dask worker with several threads) share one limit, set when the first
enters and restored when the last leaves. Dr.Jit's ray tracing keeps its own threads.
"""
from __future__ import annotations

import threading
from functools import wraps
from typing import Callable, TypeVar

from threadpoolctl import threadpool_limits

F = TypeVar("F", bound=Callable)

_LOCK = threading.Lock()
_held = {"depth": 0, "limits": None}   # limited calls running, and the limit they share


def one_blas_thread(function: F) -> F:
    """``function`` run with BLAS limited to one thread (the caller's limit restored when the
    last limited call running in the process returns)."""
    @wraps(function)
    def limited(*args, **kwargs):
        with _LOCK:
            if _held["depth"] == 0:
                _held["limits"] = threadpool_limits(limits=1, user_api="blas")
            _held["depth"] += 1
        try:
            return function(*args, **kwargs)
        finally:
            with _LOCK:
                _held["depth"] -= 1
                if _held["depth"] == 0:
                    _held["limits"].restore_original_limits()
                    _held["limits"] = None
    return limited  # type: ignore[return-value]
