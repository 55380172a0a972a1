"""Outfits as glTF 2.0 binary (DESIGN.md section 6): metres, Y up, one node and material per layer.

Anny's frame is Z up with the body facing -Y; glTF is Y up facing +Z, so points map
(x, y, z) -> (x, z, -y) (a rotation, no mirror: windings and normals keep their orientation).
Written with numpy and the standard library only: a JSON chunk and a binary chunk holding, per
layer, float32 positions and normals and uint32 indices.
"""

from __future__ import annotations

import json
import struct

import numpy as np

from service.geometry.mesh import vertex_normals

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


def _pad(data: bytes, fill: bytes = b"\0") -> bytes:
    return data + fill * (-len(data) % 4)


def outfit_glb(layers: list[tuple[str, np.ndarray, np.ndarray]]) -> bytes:
    """GLB bytes of ``layers``: (name, vertices (V, 3) m in Anny's frame, faces (F, 3) int)."""
    if not layers:
        raise ValueError("layers must not be empty")
    blob = bytearray()
    gltf: dict = {
        "asset": {"version": "2.0", "generator": "ulnef"},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(layers)))}],
        "nodes": [], "meshes": [], "materials": [], "accessors": [], "bufferViews": [],
    }  # fmt: skip

    def add(array: np.ndarray, target: int, component: int, kind: str, minmax: bool) -> int:
        data = np.ascontiguousarray(array).tobytes()
        gltf["bufferViews"].append(
            {"buffer": 0, "byteOffset": len(blob), "byteLength": len(data), "target": target}
        )
        blob.extend(_pad(data))
        accessor = {
            "bufferView": len(gltf["bufferViews"]) - 1, "componentType": component,
            "count": int(len(array) if kind == "VEC3" else array.size), "type": kind,
        }  # fmt: skip
        if minmax:
            accessor["min"] = array.min(axis=0).tolist()
            accessor["max"] = array.max(axis=0).tolist()
        gltf["accessors"].append(accessor)
        return len(gltf["accessors"]) - 1

    for i, (name, vertices, faces) in enumerate(layers):
        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or not np.all(np.isfinite(v)):
            raise ValueError(f"layer {name!r}: vertices must be finite (V, 3)")
        positions = (v @ ANNY_TO_GLTF.T).astype(np.float32)
        normals = (vertex_normals(v, f) @ ANNY_TO_GLTF.T).astype(np.float32)
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        pos = add(positions, 34962, 5126, "VEC3", True)
        nrm = add(normals, 34962, 5126, "VEC3", False)
        idx = add(f.astype(np.uint32).reshape(-1), 34963, 5125, "SCALAR", False)
        color = COLORS.get(name, (0.6, 0.6, 0.6))
        gltf["materials"].append(
            {"name": name, "doubleSided": name != "body",
             "pbrMetallicRoughness": {"baseColorFactor": [*color, 1.0], "metallicFactor": 0.0,
                                      "roughnessFactor": 0.9}}
        )  # fmt: skip
        gltf["meshes"].append(
            {"name": name, "primitives": [{"attributes": {"POSITION": pos, "NORMAL": nrm},
                                           "indices": idx, "material": i, "mode": 4}]}
        )  # fmt: skip
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
