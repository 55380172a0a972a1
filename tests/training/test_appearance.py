"""The procedural garments' look: cylinder-chart UVs (``training/garments/uv.py``) and fabric
textures (``training/garments/fabric.py``). The committed catalog's display meshes are golden files:
refresh them with ``python -m training.garments.appearance`` (then ``python -m export.manifest``)."""

from __future__ import annotations

import numpy as np
import pytest

from service.pipeline.body import BodyModel
from service.pipeline.catalog import load_catalog
from training.garments.appearance import FABRICS
from training.garments.fabric import SIZE, Fabric, base_color, height_field, normal_map
from training.garments.uv import cylinder_uv

WEAVES = ("jersey", "rib", "denim", "twill")


@pytest.fixture(scope="module")
def body():
    return BodyModel.load()


@pytest.mark.parametrize("gid", sorted(FABRICS))
def test_committed_display_meshes_are_the_charts_and_keep_lengths(gid, body):
    garment = load_catalog()[gid]
    tile = FABRICS[gid].tile
    display = cylinder_uv(garment.vertices, garment.faces, body, tile)
    display.check(len(garment.vertices), garment.faces)
    np.testing.assert_array_equal(display.source, garment.display.source)
    np.testing.assert_array_equal(display.faces, garment.display.faces)
    np.testing.assert_allclose(display.uv, garment.display.uv, atol=1e-6)
    # Seams are lines: few vertices are split (the charts' cut at the back and where parts meet).
    assert len(display.source) < 1.15 * len(garment.vertices)
    # The texture keeps its scale: an edge's length in UV x tile is its length on the cloth, for most
    # edges (a cylinder chart stretches only where the cloth turns across the axis, at the shoulders).
    corners = display.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    in_uv = np.linalg.norm(np.diff(display.uv[corners], axis=1)[:, 0], axis=1) * tile
    on_cloth = np.linalg.norm(np.diff(garment.vertices[display.source[corners]], axis=1)[:, 0], axis=1)
    ratio = in_uv / on_cloth
    assert 0.85 < np.median(ratio) < 1.15, np.median(ratio)
    assert np.mean((ratio > 0.5) & (ratio < 2.0)) > 0.9
    # No face spans the cut: the largest UV edge is a few cloth edges long, not a whole turn.
    assert in_uv.max() < 0.15, in_uv.max()


@pytest.mark.parametrize("weave", WEAVES)
def test_textures_tile_and_normals_point_out(weave):
    fabric = Fabric(weave, (0.5, 0.4, 0.3), tile=0.04)
    for image in (height_field(weave)[..., None], base_color(fabric), normal_map(fabric)):
        assert image.shape[:2] == (SIZE, SIZE) and image.min() >= 0 and image.max() <= 1
        for axis in (0, 1):
            # Across the wrap the image changes no more than between the most different neighbouring
            # rows (columns) inside it: the seam between two tiles is one more step of the pattern.
            wrap, step = wrap_and_largest_step(image, axis)
            assert wrap <= 1.25 * step + 1e-9, (axis, wrap, step)
    n = normal_map(fabric) * 2 - 1
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-9)
    assert n[..., 2].min() > 0.3


def wrap_and_largest_step(image: np.ndarray, axis: int) -> tuple[float, float]:
    """Mean change across the wrap, and the largest mean change between neighbouring rows/columns."""
    steps = np.abs(np.diff(image, axis=axis))
    per_line = steps.mean(axis=tuple(a for a in range(image.ndim) if a != axis))
    wrap = np.abs(np.take(image, 0, axis) - np.take(image, -1, axis)).mean()
    return float(wrap), float(per_line.max())


def test_a_broken_wrap_is_caught():
    """The tiling check can fail: a ramp across the tile does not wrap."""
    image = np.linspace(0, 1, SIZE)[None, :, None].repeat(SIZE, 0)
    wrap, step = wrap_and_largest_step(image, 1)
    assert not wrap <= 1.25 * step
