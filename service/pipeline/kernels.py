"""Every numba kernel of the service, and their compilation into numba's on-disk cache ahead of use.

The test session (``tests/conftest.py``) calls ``warm_kernels`` before its first test, so that no test's
time includes a compile; ``python -m service.pipeline.kernels`` compiles what the cache lacks. Where the
cache lives and how an image seeds it is ``service.process.jit_cache``'s.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

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
    # A body's girths at many heights (``measure``: the report of a body, not an outfit), on an
    # octahedron: the compiled sections take every mesh as the same array types.
    from service.geometry.girth import FEW_LEVELS, tape_girths

    octahedron = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)
    eight = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    tape_girths(octahedron, eight, np.linspace(-0.5, 0.5, FEW_LEVELS + 1), np.zeros(2))


def warm_kernels(environ: Mapping[str, str] = os.environ) -> list[str]:
    """Compile, in a child process, the kernels that numba's cache lacks (``uncached_kernels``), so that
    this process only loads them from the cache when it first calls them; returns those it compiled.

    A child process so that nothing of the outfit (models, thread settings, numba's dispatchers) stays
    in this one: the test session calls it before its first test (``tests/conftest.py``)."""
    import subprocess
    import sys

    missing = uncached_kernels()
    if missing:
        subprocess.run([sys.executable, "-m", "service.pipeline.kernels"], env=dict(environ), check=True)
    return missing


if __name__ == "__main__":
    compile_kernels()
