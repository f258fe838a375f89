"""Keep freed memory in the process instead of returning it to the kernel at once.

A scan's numpy temporaries are large (the plume test of railway with 10 000
particles allocates several 4 MB arrays per scan). glibc serves allocations
over 128 KiB-32 MiB with fresh mmaps and gives them back on free, so every
scan paid its temporaries again as page faults, zeroed by the kernel: 4-5x
the arithmetic for the plume test here, 130-160 minor faults per `physical`
scan. Raising the mmap and trim thresholds keeps those blocks in the heap
for the next scan; the cost is that the heap does not shrink after a peak.
"""

from __future__ import annotations

import ctypes
import ctypes.util

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
KEPT_BYTES = 32 * 1024 * 1024  # glibc's largest mmap threshold on 64-bit; bigger blocks still map


def keep_freed_memory() -> bool:
    """Ask glibc to serve blocks up to KEPT_BYTES from the heap and not trim it; False where
    there is no glibc `mallopt` (the process then runs as before, only slower)."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    return bool(mallopt(_M_MMAP_THRESHOLD, KEPT_BYTES)) and bool(mallopt(_M_TRIM_THRESHOLD, 4 * KEPT_BYTES))
