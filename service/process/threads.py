"""Named thread pools of a process, started once (numpy, scipy's KD-tree and onnxruntime release the
GIL, so a request's independent pieces run side by side on the cores).

Each stage owns its pool (``name``): a fit thread waits on the body map's and the closest-point
queries' threads, so one shared pool could fill with waiting tasks and deadlock. Keyed by process id
too: a forked child (a second server worker) has none of its parent's threads.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

_POOLS: dict[tuple[int, str, int], ThreadPoolExecutor] = {}
_LOCK = threading.Lock()


def pool(name: str, threads: int) -> ThreadPoolExecutor:
    """The process's pool ``name`` of ``threads`` threads, started on first use."""
    key = (os.getpid(), name, threads)
    with _LOCK:  # two requests starting at once would otherwise both start one
        if key not in _POOLS:
            _POOLS[key] = ThreadPoolExecutor(threads, thread_name_prefix=name)
        return _POOLS[key]
