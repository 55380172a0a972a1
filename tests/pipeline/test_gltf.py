"""GLB export: round trip through trimesh's reader, frame conversion, names, bad input."""

from __future__ import annotations

import io
import json
import struct

import numpy as np
import pytest
import trimesh

from service.pipeline.appearance import DisplayMesh, Material
from service.pipeline.gltf import ANNY_TO_GLTF, GltfLayer, outfit_glb
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


def _read(data: bytes):
    """(JSON document, accessor(i) -> (count, width) array, view(i) -> bytes) of a GLB."""
    (n,) = struct.unpack("<I", data[12:16])
    doc = json.loads(data[20 : 20 + n])
    binary = data[20 + n + 8 :]

    def view(i: int) -> bytes:
        v = doc["bufferViews"][i]
        return binary[v["byteOffset"] : v["byteOffset"] + v["byteLength"]]

    def accessor(i: int) -> np.ndarray:
        a = doc["accessors"][i]
        dtype = {5126: np.float32, 5125: np.uint32}[a["componentType"]]
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[a["type"]]
        return np.frombuffer(view(a["bufferView"]), dtype, a["count"] * width).reshape(a["count"], width)

    return doc, accessor, view


def _per_wedge(v, f) -> DisplayMesh:
    """Every face corner its own display vertex: the most seams a display mesh can have."""
    source = f.reshape(-1)
    return DisplayMesh(source, (v[source, :2] * 2).astype(np.float32), np.arange(f.size).reshape(f.shape))


def _png(rgb) -> bytes:
    from training.render import png_bytes

    return png_bytes(np.broadcast_to(np.asarray(rgb, dtype=float), (4, 4, 3)))


def test_display_mesh_uvs_and_textures_round_trip():
    v, f = grid_mesh(3)
    display = _per_wedge(v, f)
    cloth, normal = _png([0.8, 0.2, 0.2]), _png([0.5, 0.5, 1.0])
    material = Material((1.0, 1.0, 1.0, 1.0), 0.7, {"base_color": cloth, "normal": normal})
    layers = [
        GltfLayer("body", v * 0.5, f),
        GltfLayer("tshirt", v + [0, 0, 0.1], f, display, material),
        GltfLayer("jacket", v + [0, 0, 0.2], f, display, Material(textures={"base_color": cloth})),
    ]
    doc, accessor, view = _read(outfit_glb(layers))
    body, tshirt, jacket = (m["primitives"][0] for m in doc["meshes"])
    assert "TEXCOORD_0" not in body["attributes"] and "baseColorTexture" not in doc["materials"][0]
    np.testing.assert_allclose(accessor(tshirt["attributes"]["POSITION"]),
                               (v[display.source] + [0, 0, 0.1]) @ ANNY_TO_GLTF.T, atol=1e-6)  # fmt: skip
    np.testing.assert_array_equal(accessor(tshirt["attributes"]["TEXCOORD_0"]), display.uv)
    np.testing.assert_array_equal(accessor(tshirt["indices"]).reshape(-1, 3), display.faces)
    # Normals are the simulation mesh's: the copies of a vertex on either side of a seam agree.
    normals = accessor(tshirt["attributes"]["NORMAL"])
    for s in np.unique(display.source):
        assert np.ptp(normals[display.source == s], axis=0).max() == 0
    pbr = doc["materials"][1]["pbrMetallicRoughness"]
    assert pbr["baseColorFactor"] == [1.0, 1.0, 1.0, 1.0] and pbr["roughnessFactor"] == 0.7
    # Each distinct image is embedded once, byte for byte, and shared by the layers using it.
    images = [view(image["bufferView"]) for image in doc["images"]]
    assert sorted(images) == sorted([cloth, normal])
    base = doc["textures"][pbr["baseColorTexture"]["index"]]["source"]
    assert images[base] == cloth
    assert doc["materials"][2]["pbrMetallicRoughness"]["baseColorTexture"] == pbr["baseColorTexture"]
    assert images[doc["textures"][doc["materials"][1]["normalTexture"]["index"]]["source"]] == normal
    assert doc["samplers"] == [{"magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497}]


def test_a_layer_without_appearance_is_written_as_before():
    """No display mesh, no material: the flat-colour layer of before, with no image tables."""
    v, f = grid_mesh(2)
    assert outfit_glb([("tshirt", v, f)]) == outfit_glb([GltfLayer("tshirt", v, f)])
    doc, _, _ = _read(outfit_glb([("tshirt", v, f)]))
    assert "images" not in doc and "textures" not in doc and "samplers" not in doc
    assert doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] == [0.70, 0.25, 0.22, 1.0]


def test_a_display_mesh_that_is_not_the_simulation_mesh_is_refused():
    v, f = grid_mesh(2)
    good = _per_wedge(v, f)
    wrong_face = DisplayMesh(good.source, good.uv, good.faces[:, ::-1].copy())
    with pytest.raises(ValueError, match="not the simulation faces"):
        outfit_glb([GltfLayer("tshirt", v, f, wrong_face)])
    with pytest.raises(ValueError, match="source indices outside"):
        outfit_glb([GltfLayer("tshirt", v, f, DisplayMesh(good.source + len(v), good.uv, good.faces))])
    with pytest.raises(ValueError, match="do not fit"):
        outfit_glb([GltfLayer("tshirt", v, f, DisplayMesh(good.source, good.uv[:, :1], good.faces))])


def test_material_checks_its_values():
    with pytest.raises(ValueError, match="base_color"):
        Material((1.2, 0, 0, 1))
    with pytest.raises(ValueError, match="not a PNG"):
        Material(textures={"base_color": b"GIF89a"})
    with pytest.raises(ValueError, match="unknown texture slot"):
        Material(textures={"roughness": _png([0, 0, 0])})
