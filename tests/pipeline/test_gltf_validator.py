"""The Khronos glTF validator (npm ``gltf-validator``) finds 0 errors in the service's GLBs.

Needs node and ``tests/js/node_modules`` (``make test`` runs ``npm ci`` there); skipped without
them except in CI, where it fails.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from service.pipeline.gltf import outfit_glb
from tests.conftest import tiny_garments
from tests.service_tools import require_node, run_node


def validate(paths: list[Path]) -> dict:
    require_node("gltf-validator")
    return json.loads(run_node("validate_glb.mjs", *map(str, paths)))


def test_outfit_glbs_have_no_validator_errors(tmp_path: Path):
    pytest.importorskip("onnxruntime")
    from service.pipeline.tryon import ModelEngine, OutfitSpec
    from service.process.paths import models_dir

    engine = ModelEngine.load(models_dir(), threads=2)
    specs = {
        "tshirt_shorts": OutfitSpec(("shorts", "tshirt"), untangle=False),
        "jacket_no_body": OutfitSpec(("jacket",), gender=1.0, height_cm=165, weight_kg=60,
                                     untangle=False, include_body=False),  # fmt: skip
    }
    paths = []
    for name, spec in specs.items():
        paths.append(tmp_path / f"{name}.glb")
        paths[-1].write_bytes(engine.make(spec).glb)
    tiny = [(g.id, g.vertices, g.faces) for g in tiny_garments()]
    paths.append(tmp_path / "tiny.glb")
    paths[-1].write_bytes(outfit_glb(tiny))
    reports = validate(paths)
    for path in paths:
        report = reports[str(path)]
        assert report["numErrors"] == 0, report["errors"]


def test_validator_catches_a_broken_glb(tmp_path: Path):
    """The check can fail: a GLB whose index points past its vertices has errors."""
    v = np.zeros((3, 3))
    good = outfit_glb([("x", v, np.array([[0, 1, 2]]))])
    bad = good.replace(b'"count":3,"type":"SCALAR"', b'"count":4,"type":"SCALAR"')
    assert bad != good
    path = tmp_path / "bad.glb"
    path.write_bytes(bad)
    assert validate([path])[str(path)]["numErrors"] > 0


@pytest.mark.parametrize("compression", ["none", "quantized", "meshopt"])
def test_a_textured_glb_has_no_validator_errors(tmp_path: Path, compression: str):
    """UVs of a display mesh with seams, base colour and normal textures, an image shared by two layers;
    compact encodings: UVs beyond [0, 1] under KHR_texture_transform (meshopt: its views decoded too)."""
    from service.pipeline.appearance import DisplayMesh, Material
    from service.pipeline.gltf import GltfLayer
    from tests.meshes import grid_mesh
    from training.render import png_bytes

    v, f = grid_mesh(4)
    source = f.reshape(-1)
    display = DisplayMesh(source, (v[source, :2] * 3).astype(np.float32), np.arange(f.size).reshape(f.shape))
    cloth = png_bytes(np.random.default_rng(0).uniform(size=(16, 16, 3)))
    bump = png_bytes(np.broadcast_to([0.5, 0.5, 1.0], (16, 16, 3)))
    knit = Material(textures={"base_color": cloth, "normal": bump})
    denim = Material((0.5, 0.5, 0.5, 1.0), 0.8, {"base_color": cloth})
    layers = [
        GltfLayer("body", v, f),
        GltfLayer("tshirt", v + [0, 0, 0.01], f, display, knit),
        GltfLayer("jacket", v + [0, 0, 0.02], f, display, denim),
    ]
    data = outfit_glb(layers, compression)
    paths = [tmp_path / "textured.glb"]
    paths[0].write_bytes(data)
    if compression == "meshopt":
        pytest.importorskip("wasmtime")
        from service.pipeline.gltf_read import decompressed

        paths.append(tmp_path / "decoded.glb")
        paths[1].write_bytes(decompressed(data))
    reports = validate(paths)
    for path in paths:
        assert reports[str(path)]["numErrors"] == 0, reports[str(path)]["errors"]


def test_the_avatar_glb_has_no_validator_errors(tmp_path: Path):
    from service.cli import main

    path = tmp_path / "avatar.glb"
    assert main(["avatar", "-o", str(path)]) == 0
    report = validate([path])[str(path)]
    assert report["numErrors"] == 0, report["errors"]
