"""The catalog's files: a garment's display mesh and material survive a save/load round trip, and a
display mesh that does not map onto its simulation mesh is refused at load."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from service.pipeline.appearance import DisplayMesh, Material
from service.pipeline.catalog import load_catalog, save_garment
from tests.conftest import tiny_garments

PNG = b"\x89PNG\r\n\x1a\n" + b"not decoded by the service"


def _dressed():
    quad = tiny_garments()[0]
    source = quad.faces.reshape(-1)  # one display vertex per face corner
    uv = np.arange(12, dtype=np.float32).reshape(6, 2) / 7
    display = DisplayMesh(source, uv, np.arange(6).reshape(2, 3))
    material = Material((0.9, 0.8, 0.7, 1.0), 0.6, {"base_color": PNG}, {"base_color": "quad.base.png"})
    return replace(quad, display=display, material=material)


def _write(directory: Path, garment) -> None:
    save_garment(directory, garment)
    (directory / "catalog.json").write_text(json.dumps({"garments": [garment.catalog_entry()]}))


def test_display_mesh_and_material_round_trip(tmp_path: Path):
    garment = _dressed()
    _write(tmp_path, garment)
    loaded = load_catalog(tmp_path)[garment.id]
    for key in ("source", "uv", "faces"):
        np.testing.assert_array_equal(getattr(loaded.display, key), getattr(garment.display, key))
    assert loaded.material == garment.material
    assert loaded.summary()["material"] == {"base_color": [0.9, 0.8, 0.7, 1.0], "roughness": 0.6,
                                            "textures": {"base_color": "quad.base.png"}}  # fmt: skip


def test_a_garment_without_a_look_has_none(tmp_path: Path):
    garment = tiny_garments()[0]
    _write(tmp_path, garment)
    loaded = load_catalog(tmp_path)[garment.id]
    assert loaded.display is None and loaded.material is None and loaded.summary()["material"] is None


def test_a_display_mesh_off_its_simulation_mesh_is_refused_at_load(tmp_path: Path):
    garment = _dressed()
    _write(tmp_path, garment)
    path = tmp_path / f"{garment.id}.npz"
    with np.load(path) as data:
        arrays = dict(data)
    arrays["display_source"] = arrays["display_source"][::-1].copy()
    np.savez(path, **arrays)
    with pytest.raises(ValueError, match="not the simulation faces"):
        load_catalog(tmp_path)
