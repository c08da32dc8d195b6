"""Process-wide settings that an MPM time loop needs to be fast.

* One OpenBLAS thread: threading made the small solves of a step 3-25x
  slower on 2-core machines.  Only effective if numpy is not imported yet.
* glibc ``malloc``: by default arrays above a threshold are ``mmap``-ed and
  returned to the OS when freed, so every step's temporaries page-fault
  afresh (measured: shape functions for 1e5 particles 205 -> 122 ns each).
  Raising the mmap and trim thresholds keeps freed memory in the heap for
  reuse.  Set ``FEMGRID_MPM_KEEP_MALLOC=1`` to leave the allocator alone.
"""

import ctypes
import os
import sys

M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_MAX = 32 * 1024 * 1024  # glibc's ceiling on 64-bit
TRIM_THRESHOLD = 1024 * 1024 * 1024


def configure() -> None:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    if os.environ.get("FEMGRID_MPM_KEEP_MALLOC") or not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_MAX)
        libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD)
    except (OSError, AttributeError):  # not glibc: nothing to tune
        pass
