"""A reference reader of the service's GLBs, every encoding (``service.pipeline.gltf.Compression``).

What the tests and ``benchmarks.glb_sizes`` decode an outfit with, to measure what a client gets:
plain float accessors, ``KHR_mesh_quantization`` (normalized integers, undone by the node's
translation / rotation / scale), ``KHR_texture_transform`` on the base colour texture, and
``EXT_meshopt_compression`` views, decoded by meshoptimizer's official decoder (by default its wasm
build in ``service.pipeline.meshopt``; a caller can pass another, the tests pass the npm package's
JavaScript decoder run by node); ``decompressed`` writes the meshopt views out decoded, for the
validator. Written from the glTF 2.0 specification and the extensions' texts,
not from the writer: it reads any scene of root nodes with one mesh each.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from service.pipeline.gltf import ANNY_TO_GLTF

COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32,
              5126: np.float32}  # fmt: skip
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
MeshoptDecode = Callable[[dict, bytes], bytes]
"""(the view's ``EXT_meshopt_compression`` object, its compressed bytes) -> the view's bytes."""


@dataclass
class Primitive:
    """One node's triangles in Anny's frame: vertices (V, 3) float64 m, faces (F, 3) int64, normals
    (V, 3) unit or None, uv (V, 2) float64 after the base colour texture's transform, or None."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None
    uv: np.ndarray | None


def _official_decode(ext: dict, encoded: bytes) -> bytes:
    from service.pipeline import meshopt

    return meshopt.decode(encoded, ext["count"], ext["byteStride"], ext["mode"], ext.get("filter", "NONE"))


def chunks(data: bytes) -> tuple[dict, bytes]:
    """(JSON document, BIN chunk) of GLB ``data``; ValueError unless it is a GLB version 2."""
    magic, version, length = struct.unpack_from("<4sII", data)
    if magic != b"glTF" or version != 2 or length != len(data):
        raise ValueError("not a GLB version 2 of its stated length")
    n, kind = struct.unpack_from("<I4s", data, 12)
    if kind != b"JSON":
        raise ValueError("the first GLB chunk must be JSON")
    doc = json.loads(data[20 : 20 + n])
    binary = b""
    if 20 + n < len(data):
        m, kind = struct.unpack_from("<I4s", data, 20 + n)
        if kind != b"BIN\0":
            raise ValueError("the second GLB chunk must be BIN")
        binary = data[28 + n : 28 + n + m]
    return doc, binary


def read_primitives(data: bytes, meshopt_decode: MeshoptDecode | None = None) -> list[Primitive]:
    """Every node of GLB ``data`` with its mesh's one triangle primitive, in Anny's frame."""
    doc, binary = chunks(data)
    decode = meshopt_decode or _official_decode
    views: dict[int, bytes] = {}

    def view(i: int) -> bytes:
        if i not in views:
            v = doc["bufferViews"][i]
            ext = v.get("extensions", {}).get("EXT_meshopt_compression")
            if ext is not None:
                if ext["buffer"] != 0:
                    raise ValueError("compressed data must be in the GLB's buffer")
                start = ext.get("byteOffset", 0)
                views[i] = decode(ext, binary[start : start + ext["byteLength"]])
                if len(views[i]) != ext["count"] * ext["byteStride"]:
                    raise ValueError(f"bufferView {i}: decoded to the wrong size")
            elif v["buffer"] == 0:
                start = v.get("byteOffset", 0)
                views[i] = binary[start : start + v["byteLength"]]
            else:
                raise ValueError(f"bufferView {i}: no data in this GLB")
        return views[i]

    def accessor(i: int) -> np.ndarray:
        """(count, width) float64 (normalized integers as the spec maps them) or int64 (indices)."""
        a = doc["accessors"][i]
        dtype, width = np.dtype(COMPONENTS[a["componentType"]]), WIDTHS[a["type"]]
        v = doc["bufferViews"][a["bufferView"]]
        stride = v.get("byteStride") or dtype.itemsize * width
        raw = np.frombuffer(view(a["bufferView"]), np.uint8)[a.get("byteOffset", 0) :]
        rows = np.lib.stride_tricks.as_strided(raw, (a["count"], dtype.itemsize * width), (stride, 1))
        values = np.ascontiguousarray(rows).view(dtype).reshape(a["count"], width)
        if a.get("normalized"):
            top = float(np.iinfo(dtype).max)
            return np.maximum(values / top, -1.0)
        return values.astype(np.float64 if dtype.kind == "f" else np.int64)

    out = []
    for node_index in doc["scenes"][doc.get("scene", 0)]["nodes"]:
        node = doc["nodes"][node_index]
        if node.get("children"):
            raise ValueError("nodes with children are not read")
        (primitive,) = doc["meshes"][node["mesh"]]["primitives"]
        if primitive.get("mode", 4) != 4:
            raise ValueError("only triangle primitives are read")
        linear, translation = node_transform(node)
        attributes = primitive["attributes"]
        positions = accessor(attributes["POSITION"]) @ linear.T + translation
        normals = None
        if "NORMAL" in attributes:
            normals = accessor(attributes["NORMAL"]) @ np.linalg.inv(linear)  # inverse transpose
            normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
            normals = normals @ ANNY_TO_GLTF
        uv = accessor(attributes["TEXCOORD_0"]) if "TEXCOORD_0" in attributes else None
        if uv is not None and "material" in primitive:
            uv = _texture_transform(doc["materials"][primitive["material"]], uv)
        faces = accessor(primitive["indices"]).reshape(-1, 3)
        if len(faces) and (faces.min() < 0 or faces.max() >= len(positions)):
            raise ValueError(f"node {node.get('name')!r}: indices outside its vertices")
        out.append(Primitive(node.get("name", ""), positions @ ANNY_TO_GLTF, faces, normals, uv))
    return out


def read_glb(
    data: bytes, meshopt_decode: MeshoptDecode | None = None
) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """[(node name, vertices (V, 3) float64 in Anny's frame, faces (F, 3) int64)] of GLB ``data``."""
    return [(p.name, p.vertices, p.faces) for p in read_primitives(data, meshopt_decode)]


def node_transform(node: dict) -> tuple[np.ndarray, np.ndarray]:
    """(linear part (3, 3), translation (3,)) of a node's ``matrix`` or translation * rotation * scale."""
    if "matrix" in node:
        m = np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T  # column-major
        return m[:3, :3], m[:3, 3]
    x, y, z, w = node.get("rotation", [0.0, 0.0, 0.0, 1.0])
    rotation = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip
    scale = np.asarray(node.get("scale", [1.0, 1.0, 1.0]), dtype=np.float64)
    return rotation * scale, np.asarray(node.get("translation", [0.0, 0.0, 0.0]), dtype=np.float64)


def _texture_transform(material: dict, uv: np.ndarray) -> np.ndarray:
    """``uv (V, 2)`` through the base colour texture's ``KHR_texture_transform`` (uv' = offset + scale
    uv), if it has one; a rotation is refused (the service writes none)."""
    info = material.get("pbrMetallicRoughness", {}).get("baseColorTexture", {})
    t = info.get("extensions", {}).get("KHR_texture_transform")
    if t is None:
        return uv
    if t.get("rotation", 0.0) != 0.0 or "texCoord" in t:
        raise ValueError("KHR_texture_transform: rotation and texCoord are not read")
    return uv * np.asarray(t.get("scale", [1.0, 1.0])) + np.asarray(t.get("offset", [0.0, 0.0]))


def decompressed(data: bytes, meshopt_decode: MeshoptDecode | None = None) -> bytes:
    """GLB ``data`` with every ``EXT_meshopt_compression`` view decoded into its buffer and the extension
    dropped: what a validator can check the data of (it cannot decode meshopt views itself)."""
    doc, binary = chunks(data)
    decode = meshopt_decode or _official_decode
    blob = bytearray()
    for v in doc["bufferViews"]:
        ext = v.pop("extensions", {}).pop("EXT_meshopt_compression", None)
        if ext is None:
            start = v.get("byteOffset", 0)
            part = binary[start : start + v["byteLength"]]
        else:
            start = ext.get("byteOffset", 0)
            part = decode(ext, binary[start : start + ext["byteLength"]])
        v["buffer"], v["byteOffset"] = 0, len(blob)
        blob.extend(part + b"\0" * (-len(part) % 4))
    doc["buffers"] = [{"byteLength": len(blob)}]
    for key in ("extensionsUsed", "extensionsRequired"):
        doc[key] = [e for e in doc.get(key, []) if e != "EXT_meshopt_compression"]
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    head = struct.pack("<4sII", b"glTF", 2, 28 + len(text) + len(blob))
    json_chunk = struct.pack("<I4s", len(text), b"JSON") + text
    return head + json_chunk + struct.pack("<I4s", len(blob), b"BIN\0") + bytes(blob)
