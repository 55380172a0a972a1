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


KERNEL_PACKAGES = ("service.geometry", "service.pipeline")
"""Where the compiled kernels live (``service.server`` and ``service.process`` hold none)."""

WARM_OUTFIT = (("pants", "tshirt"), (0.5, 0.3, 0.4))
"""The outfit that compiles every kernel (what the images run at build time): the fit, the body map,
the squeeze and the repair all run on it (``tests/process/test_jit_cache.py`` checks that)."""


def kernels() -> dict[str, object]:
    """Every compiled kernel of ``KERNEL_PACKAGES`` (their modules imported), by ``module.name``: the
    numba dispatchers defined there, without the ``inline="always"`` helpers (compiled only into their
    callers)."""
    import importlib
    import pkgutil

    from numba.core.registry import CPUDispatcher

    found = {}
    for package_name in KERNEL_PACKAGES:
        package = importlib.import_module(package_name)
        for info in pkgutil.walk_packages(package.__path__, package_name + "."):
            module = importlib.import_module(info.name)
            for name, value in vars(module).items():
                if (
                    isinstance(value, CPUDispatcher)
                    and value.py_func.__module__ == info.name
                    and value.targetoptions.get("inline", "never") == "never"
                ):
                    found[f"{info.name}.{name}"] = value
    return found


def uncached_kernels() -> list[str]:
    """The kernels (``kernels()``) with nothing compiled in numba's on-disk cache for their source as it
    is now: never compiled here, or their module edited since (numba's index is stamped with the
    source file's modification time and size)."""
    missing = []
    for name, kernel in kernels().items():
        cache = getattr(kernel, "_cache", None)
        index = getattr(getattr(cache, "_cache_file", None), "_load_index", None)
        if index is None or not index():  # no on-disk cache, or an empty or stale index
            missing.append(name)
    return sorted(missing)


def compile_kernels(models_dir: Path | None = None) -> None:
    """Compile every kernel into numba's cache by making ``WARM_OUTFIT`` in this process (~20 s on two
    cores with nothing cached, ~75 s on a busy machine; a few seconds when all is cached)."""
    import numpy as np

    from service.pipeline.outfit import OutfitModels, make_outfit

    garments, beta = WARM_OUTFIT
    models = OutfitModels.load(models_dir)
    models.warm()
    make_outfit(models, list(garments), np.asarray(beta, dtype=np.float64))
    # The service's faces are frozen (read-only) arrays; callers' own meshes (the tests', the training
    # scripts') are writable, which numba compiles as another version of the geometry kernels.
    from service.geometry.closest import ClosestPoint
    from service.geometry.mesh import face_normals, vertex_normals

    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)
    mesh = ClosestPoint.build(vertices, faces)
    mesh.on_boundary(mesh.query(np.array([[0.2, 0.3, 0.1], [2.0, 0.5, 0.0]])))
    vertex_normals(vertices, faces)
    face_normals(vertices, faces)


def warm_kernels(environ: Mapping[str, str] = os.environ) -> list[str]:
    """Compile, in a child process, the kernels that numba's cache lacks (``uncached_kernels``), so that
    this process only loads them from the cache when it first calls them; returns those it compiled.

    A child process so that nothing of the outfit (models, thread settings, numba's dispatchers) stays
    in this one: the test session calls it before its first test (``tests/conftest.py``)."""
    import subprocess
    import sys

    missing = uncached_kernels()
    if missing:
        subprocess.run([sys.executable, "-m", "service.process.jit_cache"], env=dict(environ), check=True)
    return missing


if __name__ == "__main__":
    compile_kernels()
