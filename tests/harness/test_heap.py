"""The command line's heap settings: freed temporaries are reused, not faulted in again."""
import platform
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# 40 temporaries of 16 MB allocated, filled and freed, as a solve's Jacobian is, after
# keep_freed_memory(): the minor page faults the loop makes
CHURN = r"""
import resource, sys
import numpy as np
sys.path.insert(0, {root!r})
from harness.cli.heap import keep_freed_memory
assert keep_freed_memory()
np.ones(2_000_000).sum()   # numpy's own first allocations out of the count
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(40):
    np.ones(2_000_000).sum()
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="the thresholds are glibc's")
def test_freed_temporaries_are_reused_not_faulted_in_again():
    # the first block is reused, so the loop faults in nothing (measured: 0); glibc's defaults
    # made every temporary a fresh mapping faulted in again on this machine (measured: 291
    # faults with 2 MB transparent huge pages), which depends on the machine
    run = subprocess.run([sys.executable, "-c", CHURN.format(root=str(ROOT))], capture_output=True, text=True,
                         check=True)
    assert int(run.stdout.split()[-1]) < 10


def test_keep_freed_memory_reports_whether_it_applied():
    from harness.cli.heap import keep_freed_memory

    assert keep_freed_memory() is (platform.libc_ver()[0] == "glibc")
