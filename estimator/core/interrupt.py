"""A stop request that the estimator's long loops honour between steps.

A signal handler's exception raised while Dr.Jit runs a Python callback (Mitsuba's
differentiable integrators run their loop bodies that way) can be swallowed by Dr.Jit, so
a process asked to stop would run on. A handler therefore also calls :func:`request_stop`,
and each step of a long loop calls :func:`raise_if_stop_requested`, which raises
:class:`StopRequested` from plain Python code.
"""
from __future__ import annotations

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
