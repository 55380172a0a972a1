"""Process settings that the pipeline's many mid-sized numpy temporaries need (measured, see below).

- glibc returns every freed block over its mmap threshold (128 KiB at start) to the kernel, so each
  temporary of a few thousand vertices costs fresh page faults. On this machine's VM that made
  ``a + 0.5 * b`` on 30,000 doubles take 0.21 ms of CPU instead of 0.016 ms. Raising the mmap
  threshold and the trim threshold keeps those blocks in the heap (``mallopt``).
- OpenBLAS starts a thread team for every vector op; when the cores are busy (a server under load,
  concurrent requests) a 30,000-element dot product took 0.55 ms instead of 0.005 ms. The
  parallelism worth having is between requests, so BLAS runs single-threaded (``threadpoolctl``).

``tune_process`` is idempotent and a no-op where glibc or threadpoolctl is missing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging

log = logging.getLogger(__name__)

M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD, M_ARENA_MAX = -1, -2, -3, -8  # glibc malloc.h
MMAP_THRESHOLD = 32 << 20  # bytes: blocks up to this size stay in the heap when freed
TRIM_THRESHOLD = 64 << 20  # bytes of free heap top kept instead of returned to the kernel
# Any mallopt call turns off glibc's sliding thresholds, so these must cover onnxruntime's buffers too
# (a batch of 8,192 points with gradients takes ~12 MB per layer): at a 4 MiB threshold a field at
# 30,000 points took 25 ms instead of 15 ms, its buffers mapped and unmapped on every call.
ARENA_MAX = 2
# Each malloc arena keeps up to TRIM_THRESHOLD free; glibc makes up to 8 per core for the threads
# that allocate (onnxruntime's, the body map's, the server's). Two bound what the heap keeps: the
# server with the whole catalog used held 548 MB with glibc's default and 351 MB with two
# (benchmarks/memory.py), at the same latency.
_tuned = {"done": False, "limits": None}


def tune_process(blas_threads: int = 1) -> dict[str, bool]:
    """Apply both settings once per process; returns which of them took effect."""
    if _tuned["done"]:
        return _tuned["applied"]
    applied = {"malloc": False, "blas": False}
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        mallopt = None
    if mallopt is not None:
        applied["malloc"] = all(
            mallopt(param, value) == 1
            for param, value in ((M_MMAP_THRESHOLD, MMAP_THRESHOLD), (M_TRIM_THRESHOLD, TRIM_THRESHOLD),
                                 (M_TOP_PAD, 4 << 20), (M_ARENA_MAX, ARENA_MAX))
        )  # fmt: skip
    try:
        from threadpoolctl import threadpool_limits

        _tuned["limits"] = threadpool_limits(blas_threads, user_api="blas")
        applied["blas"] = True
    except ImportError:
        log.info("threadpoolctl not installed: BLAS keeps its default thread count")
    _tuned.update(done=True, applied=applied)
    return applied
