"""Compact GLB encodings (``service.pipeline.gltf_compact``) against the plain one, through the reference
reader (``service.pipeline.gltf_read``), on small meshes; the real outfit is in test_gltf_encodings."""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np
import pytest

from service.pipeline.appearance import DisplayMesh, Material
from service.pipeline.gltf import MESHOPT, GltfLayer, outfit_glb
from service.pipeline.gltf_compact import POSITION_MAX, UV_MAX
from service.pipeline.gltf_read import chunks, read_glb, read_primitives
from tests.meshes import grid_mesh
from tests.service_tools import NODE_MODULES, require_node, run_node

pytest.importorskip("wasmtime")


def _png(seed: int) -> bytes:
    from training.render import png_bytes

    return png_bytes(np.random.default_rng(seed).uniform(size=(8, 8, 3)))


def _layers(uv_scale: float = 3.0, textured: bool = True) -> list[GltfLayer]:
    """A body, a T-shirt with a display mesh (a seam at every corner) and a jacket; UVs from
    ``uv_scale`` times the xy of the vertices (tiling beyond [0, 1] when above 1)."""
    grid, f = grid_mesh(6)
    v = grid * [0.6, 0.4, 1.0] + [0.1, -0.2, 0.3]
    source = f.reshape(-1)
    uv = (grid[source, :2] * uv_scale).astype(np.float32)
    display = DisplayMesh(source, uv, np.arange(f.size).reshape(f.shape))
    material = Material(textures={"base_color": _png(0), "normal": _png(1)}) if textured else None
    return [
        GltfLayer("body", v, f),
        GltfLayer("tshirt", v + [0, 0, 0.01], f, display, material),
        GltfLayer("jacket", v + [0, 0, 0.02], f, display, material),
    ]


def _triangles(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 9) corner coordinates of each triangle, rotated to start at its smallest corner (winding
    kept), rows sorted: the same for the same triangles in any vertex or triangle order."""
    corners = vertices[faces]  # (F, 3, 3)
    keys = [tuple(map(tuple, c)) for c in corners]
    first = np.array([min(range(3), key=lambda k, c=c: c[k]) for c in keys])
    rolled = np.stack([np.roll(c, -k, axis=0) for c, k in zip(corners, first, strict=True)])
    flat = rolled.reshape(len(faces), 9)
    return flat[np.lexsort(flat.T[::-1])]


def test_quantized_is_the_plain_outfit_within_its_grids():
    layers = _layers()
    plain = read_primitives(outfit_glb(layers))
    data = outfit_glb(layers, "quantized")
    doc, _ = chunks(data)
    assert doc["extensionsRequired"] == ["KHR_mesh_quantization", "KHR_texture_transform"]
    assert doc["extensionsUsed"] == doc["extensionsRequired"]
    for p, q, node in zip(plain, read_primitives(data), doc["nodes"], strict=True):
        assert p.name == q.name
        # each coordinate within half a grid step (plus float32 of the plain one)
        step = node["scale"][0] / POSITION_MAX
        assert np.abs(q.vertices - p.vertices).max() <= 0.5 * step + 1e-6
        np.testing.assert_array_equal(q.faces, p.faces)
        cos = np.clip(np.sum(p.normals * q.normals, axis=1), -1, 1)
        assert np.degrees(np.arccos(cos)).max() < 0.6
        if p.uv is not None:
            material = doc["materials"][doc["meshes"][node["mesh"]]["primitives"][0]["material"]]
            info = material["pbrMetallicRoughness"]["baseColorTexture"]
            scale = np.asarray(info["extensions"]["KHR_texture_transform"]["scale"])
            assert np.all(np.abs(q.uv - p.uv) <= 0.5 * scale / UV_MAX + 1e-6)
    for i, mesh in enumerate(doc["meshes"]):
        attributes = mesh["primitives"][0]["attributes"]
        kinds = {k: doc["accessors"][a]["componentType"] for k, a in attributes.items()}
        assert kinds == ({"POSITION": 5122, "NORMAL": 5120} | ({"TEXCOORD_0": 5123} if i else {}))
        assert all(doc["accessors"][a]["normalized"] for a in attributes.values())
        assert doc["accessors"][mesh["primitives"][0]["indices"]]["componentType"] == 5123
    assert all(v["byteStride"] % 4 == 0 for v in doc["bufferViews"] if "byteStride" in v)
    assert all(v["byteOffset"] % 4 == 0 for v in doc["bufferViews"])


def test_the_texture_transform_goes_on_every_texture_of_a_layer_whose_uvs_leave_the_unit_square():
    doc, _ = chunks(outfit_glb(_layers(), "quantized"))
    for material in doc["materials"][1:]:
        for info in (material["pbrMetallicRoughness"]["baseColorTexture"], material["normalTexture"]):
            t = info["extensions"]["KHR_texture_transform"]
            assert set(t) == {"offset", "scale"} and min(t["scale"]) > 1  # the UVs span several tiles
    # UVs in [0, 1]: stored as they are, no transform and no extension for it
    doc, _ = chunks(outfit_glb(_layers(uv_scale=0.5), "quantized"))
    assert "KHR_texture_transform" not in json.dumps(doc)
    # UVs outside [0, 1] and no texture to carry a transform: float UVs
    untextured = outfit_glb(_layers(textured=False), "quantized")
    doc, _ = chunks(untextured)
    uv = doc["accessors"][doc["meshes"][1]["primitives"][0]["attributes"]["TEXCOORD_0"]]
    assert uv["componentType"] == 5126 and "normalized" not in uv
    np.testing.assert_array_equal(read_primitives(untextured)[1].uv, _layers()[1].display.uv)


def test_meshopt_holds_the_quantized_triangles_in_another_order():
    layers = _layers()
    quantized = read_glb(outfit_glb(layers, "quantized"))
    data = outfit_glb(layers, "meshopt")
    for (name, vq, fq), (name_m, vm, fm) in zip(quantized, read_glb(data), strict=True):
        assert name == name_m and len(vm) == len(vq) and len(fm) == len(fq)
        np.testing.assert_array_equal(_triangles(vm, fm), _triangles(vq, fq))
    doc, binary = chunks(data)
    assert doc["extensionsRequired"][:2] == ["KHR_mesh_quantization", "EXT_meshopt_compression"]
    main, fallback = doc["buffers"]
    assert main == {"byteLength": len(binary)} and "uri" not in fallback
    assert fallback["extensions"] == {"EXT_meshopt_compression": {"fallback": True}}
    compressed = [v for v in doc["bufferViews"] if "extensions" in v]
    assert len(compressed) == 3 * 3 + 2  # positions, normals, indices; the garments' UVs
    for view in compressed:
        ext = view["extensions"][MESHOPT]
        assert view["buffer"] == 1 and ext["buffer"] == 0 and ext["byteOffset"] % 4 == 0
        assert ext["count"] * ext["byteStride"] == view["byteLength"]
        assert ext["mode"] == ("TRIANGLES" if view["target"] == 34963 else "ATTRIBUTES")
    for mesh in doc["meshes"]:
        normals = doc["accessors"][mesh["primitives"][0]["attributes"]["NORMAL"]]
        assert doc["bufferViews"][normals["bufferView"]]["extensions"][MESHOPT]["filter"] == "OCTAHEDRAL"
    assert len(data) < len(outfit_glb(layers, "quantized"))


def test_a_vertex_of_no_triangle_survives_the_reordering():
    v, f = grid_mesh(3)
    v = np.vstack([v, [[5.0, 5.0, 5.0]]])
    ((_, vm, fm),) = read_glb(outfit_glb([("tshirt", v, f)], "meshopt"))
    ((_, vq, fq),) = read_glb(outfit_glb([("tshirt", v, f)], "quantized"))
    np.testing.assert_array_equal(np.sort(vm, axis=0), np.sort(vq, axis=0))
    np.testing.assert_array_equal(_triangles(vm, fm), _triangles(vq, fq))


def test_a_layer_of_65535_vertices_or_more_keeps_uint32_indices():
    n = 65535
    rng = np.random.default_rng(0)
    v = rng.uniform(-1, 1, (n, 3))
    f = np.arange(n - n % 3).reshape(-1, 3)
    for compression in ("quantized", "meshopt"):
        data = outfit_glb([("body", v, f)], compression)
        doc, _ = chunks(data)
        assert doc["accessors"][doc["meshes"][0]["primitives"][0]["indices"]]["componentType"] == 5125
        ((_, vd, fd),) = read_glb(data)
        ((_, vq, fq),) = read_glb(outfit_glb([("body", v, f)], "quantized"))
        np.testing.assert_array_equal(_triangles(vd, fd), _triangles(vq, fq))
    small = outfit_glb([("body", v[:-3], f[:-1])], "quantized")
    doc, _ = chunks(small)
    assert doc["accessors"][doc["meshes"][0]["primitives"][0]["indices"]]["componentType"] == 5123
    assert len(read_glb(small)[0][1]) == n - 3


def test_an_unknown_compression_is_refused():
    v, f = grid_mesh(2)
    with pytest.raises(ValueError, match=r"compression must be one of \('none', 'quantized', 'meshopt'\)"):
        outfit_glb([("tshirt", v, f)], "draco")


def test_the_vendored_meshopt_files_are_the_npm_package_s():
    """One decoder file for the page and the reader; both, and the encoder, as npm ships them."""
    from service.pipeline.meshopt import DECODER_JS, ENCODER_JS
    from service.server.routes.page import STATIC_DIR

    assert (STATIC_DIR / "vendor" / "meshopt_decoder.js").read_bytes() == DECODER_JS.read_bytes()
    package = NODE_MODULES / "meshoptimizer"
    require_node("meshoptimizer")
    assert json.loads((package / "package.json").read_text())["version"] == "1.3.0"
    assert ENCODER_JS.read_bytes() == (package / "meshopt_encoder.js").read_bytes()
    assert DECODER_JS.read_bytes() == (package / "meshopt_decoder.cjs").read_bytes()


def node_decoder(data: bytes, tmp_path: Path):
    """A ``MeshoptDecode`` answering from the npm package's JavaScript decoder, run by node on ``data``."""
    path = tmp_path / "meshopt.glb"
    path.write_bytes(data)
    answer = json.loads(run_node("meshopt_decode.mjs", str(path)))
    decoded = {int(k): base64.b64decode(v) for k, v in answer.items()}
    return lambda ext, encoded: decoded[ext.get("byteOffset", 0)]


def test_the_npm_decoder_decodes_what_the_wasm_decoder_does(tmp_path: Path):
    require_node("meshoptimizer")
    data = outfit_glb(_layers(), "meshopt")
    by_node = read_primitives(data, node_decoder(data, tmp_path))
    for a, b in zip(read_primitives(data), by_node, strict=True):
        np.testing.assert_array_equal(a.vertices, b.vertices)
        np.testing.assert_array_equal(a.faces, b.faces)
        np.testing.assert_array_equal(a.normals, b.normals)
        if a.uv is not None:
            np.testing.assert_array_equal(a.uv, b.uv)


def test_threads_encode_what_one_thread_does():
    """One wasm instance per thread: concurrent requests encode the same bytes as one at a time."""
    from concurrent.futures import ThreadPoolExecutor

    layers = _layers()
    expected = outfit_glb(layers, "meshopt")
    with ThreadPoolExecutor(4) as pool:
        assert set(pool.map(lambda _: outfit_glb(layers, "meshopt"), range(8))) == {expected}


def test_malformed_meshopt_data_is_refused():
    from service.pipeline import meshopt

    good = meshopt.encode_attributes(np.arange(64, dtype=np.int16).reshape(16, 4))
    assert np.array_equal(np.frombuffer(meshopt.decode(good, 16, 8, "ATTRIBUTES"), np.int16), np.arange(64))
    top = meshopt._local.decoder.call("sbrk", 0)
    with pytest.raises(ValueError, match="malformed meshopt buffer data"):
        meshopt.decode(good[:-8], 16, 8, "ATTRIBUTES")
    assert meshopt._local.decoder.call("sbrk", 0) == top  # what the failed call allocated is freed


def _with_node(data: bytes, **fields) -> bytes:
    """GLB ``data`` with ``fields`` set on its first node."""
    import struct

    doc, binary = chunks(data)
    doc["nodes"][0] |= fields
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    return (struct.pack("<4sII", b"glTF", 2, 28 + len(text) + len(binary))
            + struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(binary), b"BIN\0")
            + binary)  # fmt: skip


def test_the_reader_applies_node_rotations_and_matrices():
    """A quarter turn about glTF's up axis, as a quaternion and as a matrix, with a translation."""
    v, f = grid_mesh(2)
    data = outfit_glb([("tshirt", v, f)])
    ((_, plain, _),) = read_glb(data)
    s = np.sqrt(0.5)
    turned = _with_node(data, rotation=[0.0, s, 0.0, s], translation=[1.0, 2.0, 3.0])
    matrix = [0, 0, -1, 0, 0, 1, 0, 0, 1, 0, 0, 0, 1, 2, 3, 1]  # column-major: x -> -z, z -> x
    for glb in (turned, _with_node(data, matrix=matrix)):
        ((_, moved, _),) = read_glb(glb)
        # in Anny's frame: glTF x -> -z is x -> y; the translation (1, 2, 3) is (1, -3, 2)
        expected = np.stack([plain[:, 1], -plain[:, 0], plain[:, 2]], axis=1) * [-1, -1, 1] + [1, -3, 2]
        np.testing.assert_allclose(moved, expected, atol=1e-6)
