"""Keeping freed memory in the process while it renders: fewer page faults per frame.

Cycles, OIDN and the image writers allocate and free the same large buffers for every frame. With
glibc's defaults, blocks above a dynamic threshold are handed back to the kernel when freed
(``munmap`` / heap trimming) and the next frame faults them in again, zero-filled.
:func:`keep_freed_memory` raises glibc's mmap and trim thresholds (``mallopt``) so that those
buffers are reused. Measured on 24-frame 256² MOVi scenes (docs/render-cost.md, four alternating
pairs each): about 0.5 CPU-s of system time less per scene — 2 % of a MOVi-A scene at 8 spp,
1.4 % of a MOVi-C one — for 40–45 MiB more peak RSS with OIDN's FAST prefilter and 90–100 MiB with
its ACCURATE one. Worth it only where a scene is cheap, so it is an option:
``Blender(keep_freed_memory=True)``, which the ``fast`` and ``draft`` quality profiles set.

Once applied it holds for the rest of the process. The environment variable
``KUBRIC_MALLOC_TUNING=0`` keeps glibc's defaults even where it is asked for (the benchmark's A/B);
it does nothing where the C library is not glibc.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

#: mallopt parameters (glibc's malloc.h)
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
#: blocks below 64 MiB come from the heap (reused when freed); up to 64 MiB of free heap is kept.
#: 512 MiB / 1 GiB measured the same CPU time (within noise) for more retained memory.
MMAP_THRESHOLD, TRIM_THRESHOLD = 64 * 2**20, 64 * 2**20

_applied: bool | None = None


def keep_freed_memory() -> bool:
    """Raise glibc's mmap / trim thresholds once per process; True when they are raised."""
    global _applied
    if _applied is None:
        _applied = False
        if os.environ.get("KUBRIC_MALLOC_TUNING", "1").strip() != "0":
            try:
                libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
                mallopt = libc.mallopt
            except (OSError, AttributeError):  # not glibc: nothing to tune
                return False
            mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
            _applied = bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and \
                bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
    return _applied
