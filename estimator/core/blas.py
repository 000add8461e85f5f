"""How many threads the estimator's dense linear algebra runs on: one by default, for a whole
estimate (the setting ``blas_threads``, :class:`estimator.rays.backend.BackendConfig`).

Its BLAS products are many and small: each Gauss-Newton step of the edge fit forms a (k, F) x
(F, k) product (k = 24 light coefficients, F = 5k faces: about 1.4 ms), the trust diagnostics'
Gram matrices are (M, M). At that size a second OpenBLAS thread costs about what it saves, and
when other work shares the cores its threads wait on each other: on the 2-core development
machine, with one other process running, the default method's estimate of a 5k-face real-light
scene took 28.6 s with OpenBLAS's two threads and 5.6 s with one (the edge fit's product 18 ms a
call); alone on the machine the two took the same time. A large problem on a machine with many
idle cores (a dense scan's (M, M) Gram matrices over millions of rows) may gain from more
threads: ``blas_threads`` sets the count, 0 leaves the process's own.

:func:`limited_blas` limits BLAS through ``threadpoolctl`` (which finds the BLAS library numpy
and scipy loaded, whichever it is) and restores the caller's setting after. The limit is the
process's: estimates running in several threads at once (a Dask worker with several threads)
share one limit, the first's, set when it enters and restored when the last leaves. Dr.Jit's ray
tracing keeps its own threads.
"""
from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

from threadpoolctl import threadpool_limits

_LOCK = threading.Lock()
_held = {"depth": 0, "limits": None}   # limited blocks running, and the limit they share


@contextmanager
def limited_blas(threads: int = 1) -> Iterator[None]:
    """The block runs with BLAS limited to ``threads`` threads (0: the process's setting, not
    touched); the caller's limit is restored when the last limited block running in the process
    leaves. A block entered while another runs shares that one's limit."""
    if threads == 0:
        yield
        return
    with _LOCK:
        if _held["depth"] == 0:
            _held["limits"] = threadpool_limits(limits=threads, user_api="blas")
        _held["depth"] += 1
    try:
        yield
    finally:
        with _LOCK:
            _held["depth"] -= 1
            if _held["depth"] == 0:
                _held["limits"].restore_original_limits()
                _held["limits"] = None
