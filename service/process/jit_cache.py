"""numba's compiled kernels, cached where a read-only image can use them.

numba caches a compiled function beside its source or in ``NUMBA_CACHE_DIR``, and only in a folder
it can write to: on a read-only root filesystem that is the tmpfs ``/tmp``, empty at every start, so
each start would compile every kernel again (~7 s of a 10 s start). The images compile them at build
time into ``ULNEF_JIT_CACHE_SEED`` (read-only at run time); ``seed_jit_cache`` copies that seed into
the empty ``NUMBA_CACHE_DIR`` before any kernel is called. numba checks each cached entry against its
source file's stamp, so a seed from another build is ignored, never wrongly used.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Mapping
from pathlib import Path


def seed_jit_cache(environ: Mapping[str, str] = os.environ) -> bool:
    """Copy ``ULNEF_JIT_CACHE_SEED`` into ``NUMBA_CACHE_DIR`` when both are set, the seed exists and the
    cache holds no file yet (missing, empty, or only folders); True when it copied.

    Only folders: numba makes (and checks it can write) a kernel module's cache folder when the module
    is imported, before any kernel runs, and ``service.geometry.mesh`` is imported before the command
    line is even parsed. Seeding only an empty cache skipped the seed then, and every kernel compiled
    again at start (12 s to ready in the image instead of 3)."""
    seed, cache = environ.get("ULNEF_JIT_CACHE_SEED"), environ.get("NUMBA_CACHE_DIR")
    if not seed or not cache or not Path(seed).is_dir():
        return False
    target = Path(cache)
    if target.is_dir() and any(p.is_file() for p in target.rglob("*")):
        return False
    shutil.copytree(seed, target, dirs_exist_ok=True)
    return True
