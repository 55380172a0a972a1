"""Outfits as glTF 2.0 binary (DESIGN.md section 6): metres, Y up, one node and material per layer.

Anny's frame is Z up with the body facing -Y; glTF is Y up facing +Z, so points map
(x, y, z) -> (x, z, -y) (a rotation, no mirror: windings and normals keep their orientation).
Written with numpy and the standard library only: a JSON chunk and a binary chunk holding, per
layer, float32 positions and normals and uint32 indices; a layer with a display mesh
(``service.pipeline.appearance``) also gets TEXCOORD_0, and its material's PNG textures are embedded
(each distinct image once). Normals come from the simulation mesh, so they stay smooth across UV seams
(a display mesh embedded in a remeshed simulation mesh interpolates them).
"""

from __future__ import annotations

import hashlib
import json
import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from service.geometry.mesh import vertex_normals
from service.pipeline.appearance import DisplayMesh, Material

ANNY_TO_GLTF = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
COLORS = {
    "body": (0.87, 0.72, 0.62),
    "tank_top": (0.85, 0.68, 0.25),
    "tshirt": (0.70, 0.25, 0.22),
    "long_sleeve": (0.50, 0.62, 0.48),
    "jacket": (0.25, 0.26, 0.28),
    "pants": (0.22, 0.33, 0.52),
    "shorts": (0.20, 0.52, 0.52),
    "skirt": (0.48, 0.28, 0.45),
}


# glTF sampler: linear filtering, mipmaps, repeat (fabric textures tile).
REPEAT_SAMPLER = {"magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497}


@dataclass(frozen=True)
class GltfLayer:
    """One node: vertices (V, 3) m in Anny's frame, faces (F, 3) int; optional display mesh and material
    (without a material the layer gets its flat colour from ``COLORS``)."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    display: DisplayMesh | None = None
    material: Material | None = None


def _pad(data: bytes, fill: bytes = b"\0") -> bytes:
    return data + fill * (-len(data) % 4)


def outfit_glb(layers: Sequence[GltfLayer | tuple]) -> bytes:
    """GLB bytes of ``layers``: ``GltfLayer``s, or tuples of its fields (name, vertices, faces[, display,
    material])."""
    layers = [layer if isinstance(layer, GltfLayer) else GltfLayer(*layer) for layer in layers]
    if not layers:
        raise ValueError("layers must not be empty")
    blob = bytearray()
    gltf: dict = {
        "asset": {"version": "2.0", "generator": "ulnef"},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(layers)))}],
        "nodes": [], "meshes": [], "materials": [], "accessors": [], "bufferViews": [],
    }  # fmt: skip

    def add_view(data: bytes, target: int | None) -> int:
        view = {"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)}
        gltf["bufferViews"].append(view if target is None else view | {"target": target})
        blob.extend(_pad(data))
        return len(gltf["bufferViews"]) - 1

    def add(array: np.ndarray, target: int, component: int, kind: str, minmax: bool) -> int:
        accessor = {
            "bufferView": add_view(np.ascontiguousarray(array).tobytes(), target), "componentType": component,
            "count": int(array.size if kind == "SCALAR" else len(array)), "type": kind,
        }  # fmt: skip
        if minmax:
            accessor["min"] = array.min(axis=0).tolist()
            accessor["max"] = array.max(axis=0).tolist()
        gltf["accessors"].append(accessor)
        return len(gltf["accessors"]) - 1

    images: dict[str, int] = {}  # sha256 of the PNG -> texture index

    def texture(png: bytes) -> int:
        key = hashlib.sha256(png).hexdigest()
        if key not in images:
            gltf.setdefault("samplers", [REPEAT_SAMPLER])
            gltf.setdefault("images", []).append({"bufferView": add_view(png, None), "mimeType": "image/png"})
            gltf.setdefault("textures", []).append({"sampler": 0, "source": len(gltf["images"]) - 1})
            images[key] = len(gltf["textures"]) - 1
        return images[key]

    for i, layer in enumerate(layers):
        name = layer.name
        v = np.asarray(layer.vertices, dtype=np.float64)
        f = np.asarray(layer.faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or not np.all(np.isfinite(v)):
            raise ValueError(f"layer {name!r}: vertices must be finite (V, 3)")
        if layer.display is not None:
            layer.display.check(len(v), f)
        normals = (vertex_normals(v, f) @ ANNY_TO_GLTF.T).astype(np.float32)
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        attributes, faces = {}, f
        if layer.display is not None:
            (v, normals), faces = layer.display.place(v, f, normals), layer.display.faces
            normals = normals.astype(np.float32)
        attributes["POSITION"] = add((v @ ANNY_TO_GLTF.T).astype(np.float32), 34962, 5126, "VEC3", True)
        attributes["NORMAL"] = add(normals, 34962, 5126, "VEC3", False)
        if layer.display is not None:
            attributes["TEXCOORD_0"] = add(layer.display.uv.astype(np.float32), 34962, 5126, "VEC2", False)
        idx = add(np.asarray(faces).astype(np.uint32).reshape(-1), 34963, 5125, "SCALAR", False)
        textures = texture if layer.display is not None else None
        gltf["materials"].append(_material(name, layer.material, textures))
        primitive = {"attributes": attributes, "indices": idx, "material": i, "mode": 4}
        gltf["meshes"].append({"name": name, "primitives": [primitive]})
        gltf["nodes"].append({"name": name, "mesh": i})
    gltf["buffers"] = [{"byteLength": len(blob)}]
    text = _pad(json.dumps(gltf, separators=(",", ":")).encode(), b" ")
    body = bytes(blob)
    length = 12 + 8 + len(text) + 8 + len(body)
    return (
        struct.pack("<4sII", b"glTF", 2, length)
        + struct.pack("<I4s", len(text), b"JSON") + text
        + struct.pack("<I4s", len(body), b"BIN\0") + body
    )  # fmt: skip


def _material(name: str, material: Material | None, texture) -> dict:
    """The glTF material of a layer; ``texture(png) -> index`` embeds an image (None: no UVs, so no
    textures)."""
    color = (*COLORS.get(name, (0.6, 0.6, 0.6)), 1.0) if material is None else material.base_color
    pbr = {"baseColorFactor": [*color], "metallicFactor": 0.0,
           "roughnessFactor": 0.9 if material is None else material.roughness}  # fmt: skip
    out = {"name": name, "doubleSided": name != "body", "pbrMetallicRoughness": pbr}
    if material is not None and texture is not None:
        if "base_color" in material.textures:
            pbr["baseColorTexture"] = {"index": texture(material.textures["base_color"])}
        if "normal" in material.textures:
            out["normalTexture"] = {"index": texture(material.textures["normal"])}
    return out
