"""GLB export: round trip through trimesh's reader, frame conversion, names, bad input."""

from __future__ import annotations

import io
import json
import struct

import numpy as np
import pytest
import trimesh

from service.pipeline.gltf import ANNY_TO_GLTF, outfit_glb
from tests.meshes import grid_mesh


def _layers():
    v, f = grid_mesh(3)
    return [("body", v * 0.5, f), ("tshirt", v * 0.5 + [0, -0.1, 1.0], f)]


def test_round_trip_names_positions_and_frame():
    layers = _layers()
    data = outfit_glb(layers)
    magic, version, length = struct.unpack("<4sII", data[:12])
    assert (magic, version, length) == (b"glTF", 2, len(data))
    scene = trimesh.load(io.BytesIO(data), file_type="glb", process=False)
    assert sorted(scene.graph.nodes_geometry) == ["body", "tshirt"]
    for name, v, f in layers:
        mesh = scene.geometry[name]
        np.testing.assert_allclose(mesh.vertices, v @ ANNY_TO_GLTF.T, atol=1e-6)
        np.testing.assert_array_equal(mesh.faces, f)
    # Anny's up (+Z) is glTF's up (+Y); its forward (-Y) is glTF's +Z.
    np.testing.assert_allclose(ANNY_TO_GLTF @ [0, 0, 1], [0, 1, 0])
    np.testing.assert_allclose(ANNY_TO_GLTF @ [0, -1, 0], [0, 0, 1])
    assert np.linalg.det(ANNY_TO_GLTF) == pytest.approx(1.0)


def test_one_material_per_layer_and_minmax():
    data = outfit_glb(_layers())
    (n,) = struct.unpack("<I", data[12:16])
    doc = json.loads(data[20 : 20 + n])
    assert [m["name"] for m in doc["materials"]] == ["body", "tshirt"]
    assert [p["material"] for m in doc["meshes"] for p in m["primitives"]] == [0, 1]
    pos = doc["accessors"][doc["meshes"][1]["primitives"][0]["attributes"]["POSITION"]]
    assert pos["max"][1] == pytest.approx(1.0)


def test_non_finite_vertices_are_refused():
    v, f = grid_mesh(2)
    v[0, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        outfit_glb([("tshirt", v, f)])
