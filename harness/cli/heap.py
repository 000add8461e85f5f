"""The C heap of a pseudolight process: freed memory kept for reuse instead of handed back.

The estimator's solves allocate and free numpy temporaries of 1-30 MB many times a second
(a Jacobian of 15k observations x 121 SH coefficients is 14.5 MB). glibc serves blocks
above its mmap threshold (128 KB, raised at run time to the largest block freed) with fresh
pages from the kernel and gives the top of its heap back once 2x that threshold lies free,
so each such temporary is faulted in again page by page. On a virtual machine a page fault
costs several microseconds: a pose refinement of earth-specular made 256k-674k minor faults
and spent 1.6-3.6 s in the kernel. With the thresholds below it makes 82k and spends 0.6 s,
and its whole run takes 1-3 s less, for 6 MB more peak memory (``benchmarks/README.md``).

The settings are process-wide, so only the process's entry points apply them (the command
line, a sweep's workers, the benchmarks); a program that calls ``estimator.estimate`` itself
may call :func:`keep_freed_memory` too.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import platform

# glibc's mallopt parameters (malloc.h)
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD = 32 << 20   # glibc's largest: blocks up to 32 MiB come from the heap and are reused
TRIM_THRESHOLD = 1 << 30    # free heap kept before its top goes back to the kernel (1 GiB)


def keep_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds (:data:`MMAP_THRESHOLD`, :data:`TRIM_THRESHOLD`)
    for this process. Returns whether they were set (False where the C library is not glibc,
    whose allocator has no such thresholds)."""
    if platform.libc_ver()[0] != "glibc":
        return False
    libc = ctypes.CDLL(ctypes.util.find_library("c"))
    return bool(libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(libc.mallopt(M_TRIM_THRESHOLD,
                                                                                    TRIM_THRESHOLD))
