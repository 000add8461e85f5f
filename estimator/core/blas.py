"""How many threads the estimator's dense linear algebra runs on: one, for a whole estimate.

Its BLAS products are many and small: each Gauss-Newton step of the edge fit forms a (k, F) x
(F, k) product (k = 24 light coefficients, F = 5k faces: about 1.4 ms), the trust diagnostics'
Gram matrices are (M, M). At that size a second OpenBLAS thread costs about what it saves, and
when other work shares the cores its threads wait on each other: on the 2-core development
machine, with one other process running, the default method's estimate of a 5k-face real-light
scene took 23.7 s with OpenBLAS's two threads and 3.5 s with one (cProfile; the edge fit's
product 18 ms a call). :func:`one_blas_thread` limits BLAS through ``threadpoolctl`` (which
finds the BLAS library numpy and scipy loaded, whichever it is) for the call and restores the
caller's setting after; Dr.Jit's ray tracing keeps its own threads.
"""
from __future__ import annotations

from functools import wraps
from typing import Callable, TypeVar

from threadpoolctl import threadpool_limits

F = TypeVar("F", bound=Callable)


def one_blas_thread(function: F) -> F:
    """``function`` run with BLAS limited to one thread (the caller's limit restored after)."""
    @wraps(function)
    def limited(*args, **kwargs):
        with threadpool_limits(limits=1, user_api="blas"):
            return function(*args, **kwargs)
    return limited  # type: ignore[return-value]
