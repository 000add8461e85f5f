"""The stop request and the deferral of signals around native imports."""
import os
import signal

import pytest

from estimator.core.interrupt import signals_deferred


class Delivered(Exception):
    pass


def test_a_signal_inside_the_block_is_delivered_after_it():
    """SIGINT sent inside ``signals_deferred`` reaches the handler only once the block is done,
    and the handler in place before the block is back."""
    def handler(signum, frame):
        raise Delivered(signum)

    previous = signal.signal(signal.SIGINT, handler)
    try:
        finished = []
        with pytest.raises(Delivered):
            with signals_deferred():
                os.kill(os.getpid(), signal.SIGINT)
                finished.append(sum(range(1000)))   # bytecode after the signal: the handler would run here
                finished.append(True)
        assert finished == [499500, True]
        assert signal.getsignal(signal.SIGINT) is handler
    finally:
        signal.signal(signal.SIGINT, previous)


def test_without_a_signal_the_block_runs_as_it_is():
    before = signal.getsignal(signal.SIGTERM)
    with signals_deferred():
        value = 2 + 2
    assert value == 4 and signal.getsignal(signal.SIGTERM) is before
