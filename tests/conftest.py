"""Shared fixtures: a tiny garment catalog on disk, and no catalog cache shared between tests."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from service.pipeline.catalog import Garment, load_catalog, save_garment
from tests.service_tools import FAKE_SIZES


@pytest.fixture(scope="session", autouse=True)
def _compiled_kernels():
    """Every numba kernel of ``service`` compiled into numba's on-disk cache before the first test
    (``service.pipeline.kernels.warm_kernels``: ~20-75 s with nothing cached, e.g. in CI or after a
    kernel module changed; ~1 s when all is cached), so that no test's time includes a compile: the
    first test to call a kernel only loads it. Not a test itself: where the outfit that compiles them
    fails, the warning says so and the tests that call the failing code fail on their own."""
    import time
    import warnings

    from service.pipeline.kernels import warm_kernels

    t0 = time.perf_counter()
    try:
        compiled = warm_kernels()
    except Exception as error:  # noqa: BLE001 - reported, and the tests still run
        warnings.warn(f"compiling the numba kernels before the tests failed: {error!r}", stacklevel=1)
        return
    if compiled:
        seconds = time.perf_counter() - t0
        print(f"\ncompiled {len(compiled)} numba kernels in {seconds:.0f} s before the tests")


@pytest.fixture(autouse=True)
def _fresh_catalog_cache():
    """``load_catalog`` is lru_cached by directory; a catalog read by one test must not leak into the next."""
    load_catalog.cache_clear()
    yield
    load_catalog.cache_clear()


def tiny_garments() -> list[Garment]:
    """Two garments small enough to check by hand: a quad with two openings and a single triangle."""
    quad = Garment(
        id="tshirt",
        name="T-shirt",
        category="top",
        layer_rank=1,
        vertices=np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], dtype=np.float64),
        faces=np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64),
        openings={"waist": np.array([0, 1]), "neck": np.array([2, 3])},
    )
    triangle = Garment(
        id="pants",
        name="Pants",
        category="bottom",
        layer_rank=0,
        vertices=np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1]], dtype=np.float64),
        faces=np.array([[0, 1, 2]], dtype=np.int64),
        openings={"waist": np.array([0, 1, 2])},
    )
    return [quad, triangle]


@pytest.fixture
def fake_models_dir(tmp_path: Path) -> Path:
    """A models directory whose ``garments/`` holds the catalog of ``tiny_garments()``, the T-shirt in
    sizes (``sizes.json``: its letters only, as ``tests.service_tools.FAKE_SIZES``)."""
    directory = tmp_path / "models" / "garments"
    entries = []
    for garment in tiny_garments():
        path = save_garment(directory, garment)
        entries.append(
            {
                "id": garment.id,
                "name": garment.name,
                "category": garment.category,
                "layer_rank": garment.layer_rank,
                "file": path.name,
            }
        )
    (directory / "catalog.json").write_text(json.dumps({"garments": entries}, indent=2))
    girths = {letter: {} for letter in FAKE_SIZES["tshirt"].letters}
    sizes = {"styles": {"tshirt": {"run": "men", "girths": girths}}}
    (directory / "sizes.json").write_text(json.dumps(sizes))
    return directory.parent
