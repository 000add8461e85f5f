"""A stop request that the estimator's long loops honour between steps.

A signal handler's exception raised while Dr.Jit runs a Python callback (Mitsuba's
differentiable integrators run their loop bodies that way) can be swallowed by Dr.Jit, so
a process asked to stop would run on. A handler therefore also calls :func:`request_stop`,
and each step of a long loop calls :func:`raise_if_stop_requested`, which raises
:class:`StopRequested` from plain Python code.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

_REQUESTED = [False]


class StopRequested(BaseException):
    """The process was asked to stop (a signal handler called :func:`request_stop`)."""


def request_stop() -> None:
    """Ask every long loop to stop at its next step (safe to call from a signal handler)."""
    _REQUESTED[0] = True


def clear_stop() -> None:
    """Forget an earlier request (a new command begins)."""
    _REQUESTED[0] = False


def raise_if_stop_requested() -> None:
    """Raise :class:`StopRequested` when a stop was requested."""
    if _REQUESTED[0]:
        raise StopRequested()


@contextmanager
def stop_signals_handled(handler):
    """SIGINT and SIGTERM handled by ``handler`` (signum, frame) while the block runs, the
    previous handlers restored after it (main thread only: no other thread can set them)."""
    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, old in previous.items():
            signal.signal(s, old)


@contextmanager
def signals_deferred():
    """Hold SIGINT and SIGTERM back while the block runs, then deliver the first that came.

    For native imports (Dr.Jit's, Mitsuba's variants): an exception raised by a signal handler
    midway through one leaves the extension half set up, and the process then crashes (a
    segmentation fault, or an abort at exit) instead of unwinding. Only the main thread
    receives signals, so elsewhere the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    with stop_signals_handled(lambda signum, frame: pending.append(signum)):
        yield
    if pending:
        signal.raise_signal(pending[0])
