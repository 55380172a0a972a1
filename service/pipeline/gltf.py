"""Outfits as glTF 2.0 binary (docs/design.md section 6): metres, Y up, one node and material per layer.

Anny's frame is Z up with the body facing -Y; glTF is Y up facing +Z, so points map
(x, y, z) -> (x, z, -y) (a rotation, no mirror: windings and normals keep their orientation).
Written with numpy and the standard library only: a JSON chunk and a binary chunk holding, per
layer, float32 positions and normals and uint32 indices; a layer with a display mesh
(``service.pipeline.appearance``) also gets TEXCOORD_0, and its material's PNG textures are embedded
(each distinct image once). Normals come from the simulation mesh, so they stay smooth across UV seams
(a display mesh embedded in a remeshed simulation mesh interpolates them).

That is ``compression="none"``. ``"quantized"`` (KHR_mesh_quantization) and ``"meshopt"``
(EXT_meshopt_compression over it) write the same layers smaller: ``service.pipeline.gltf_compact``.
``service.pipeline.gltf_read`` reads all three back (the tests' and ``benchmarks.glb_sizes``' reader).
"""

from __future__ import annotations

import hashlib
import json
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from service.geometry.mesh import vertex_normals
from service.pipeline import gltf_compact
from service.pipeline.appearance import DisplayMesh, Material

Compression = Literal["none", "quantized", "meshopt"]
"""GLB encodings: plain float32 / uint32; quantized integers; quantized then meshopt-compressed."""
QUANTIZATION, MESHOPT = "KHR_mesh_quantization", "EXT_meshopt_compression"
TEXTURE_TRANSFORM = "KHR_texture_transform"

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
    (without a material the layer gets its flat colour from ``COLORS``); ``extras``, JSON-able, go on
    the node as glTF ``extras`` (the body's measurements)."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    display: DisplayMesh | None = None
    material: Material | None = None
    extras: dict | None = None
    colors: np.ndarray | None = None
    """``(V, 3)`` RGB in 0..1 per vertex (the tension map, ``service.pipeline.tension``): written as
    COLOR_0 on the simulation mesh (the display mesh and textures left out) under a white material, in
    the plain encoding only."""


def _pad(data: bytes, fill: bytes = b"\0") -> bytes:
    return data + fill * (-len(data) % 4)


class _Writer:
    """The JSON document and the binary chunk (buffer 0) as views and accessors are added; compressed
    views (``EXT_meshopt_compression``) also take their uncompressed size in a fallback buffer (1)."""

    def __init__(self, n_layers: int):
        self.blob = bytearray()
        self.fallback = 0
        self.gltf: dict = {
            "asset": {"version": "2.0", "generator": "ulnef"},
            "scene": 0,
            "scenes": [{"nodes": list(range(n_layers))}],
            "nodes": [], "meshes": [], "materials": [], "accessors": [], "bufferViews": [],
        }  # fmt: skip

    def _append(self, key: str, item: dict) -> int:
        self.gltf[key].append(item)
        return len(self.gltf[key]) - 1

    def view(self, data: bytes, target: int | None, stride: int | None = None) -> int:
        view = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        if stride is not None:
            view["byteStride"] = stride
        self.blob.extend(_pad(data))
        return self._append("bufferViews", view if target is None else view | {"target": target})

    def meshopt_view(self, length: int, encoded: bytes, target: int, stride: int, count: int, mode: str,
                     filter: str | None = None) -> int:  # fmt: skip
        """A view of ``length`` bytes in the fallback buffer whose data are ``encoded`` in buffer 0."""
        ext = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(encoded), "byteStride": stride,
               "count": count, "mode": mode} | ({"filter": filter} if filter else {})  # fmt: skip
        self.blob.extend(_pad(encoded))
        view = {"buffer": 1, "byteOffset": self.fallback, "byteLength": length}
        view |= {"byteStride": stride} if mode == "ATTRIBUTES" else {}
        self.fallback += length + (-length % 4)
        return self._append("bufferViews", view | {"target": target, "extensions": {MESHOPT: ext}})

    def accessor(self, view: int, component: int, count: int, kind: str, normalized: bool = False,
                 minmax: tuple[list, list] | None = None) -> int:  # fmt: skip
        accessor = {"bufferView": view, "componentType": component, "count": count, "type": kind}
        if normalized:
            accessor["normalized"] = True
        if minmax is not None:
            accessor["min"], accessor["max"] = minmax
        return self._append("accessors", accessor)

    def add(self, array: np.ndarray, target: int, component: int, kind: str, minmax: bool) -> int:
        """An accessor of ``array`` as it is (the uncompressed encoding)."""
        view = self.view(np.ascontiguousarray(array).tobytes(), target)
        count = int(array.size if kind == "SCALAR" else len(array))
        return self.accessor(view, component, count, kind, False,
                             (array.min(axis=0).tolist(), array.max(axis=0).tolist()) if minmax else None)

    def glb(self, extensions: list[str]) -> bytes:
        gltf = self.gltf
        if extensions:
            gltf["extensionsUsed"] = gltf["extensionsRequired"] = extensions
        gltf["buffers"] = [{"byteLength": len(self.blob)}]
        if self.fallback:
            gltf["buffers"].append({"byteLength": self.fallback, "extensions": {MESHOPT: {"fallback": True}}})
        text = _pad(json.dumps(gltf, separators=(",", ":")).encode(), b" ")
        body = bytes(self.blob)
        length = 12 + 8 + len(text) + 8 + len(body)
        return (
            struct.pack("<4sII", b"glTF", 2, length)
            + struct.pack("<I4s", len(text), b"JSON") + text
            + struct.pack("<I4s", len(body), b"BIN\0") + body
        )  # fmt: skip


def outfit_glb(layers: Sequence[GltfLayer | tuple], compression: Compression = "none") -> bytes:
    """GLB bytes of ``layers``: ``GltfLayer``s, or tuples of its fields (name, vertices, faces[, display,
    material]); ``compression`` as in ``service.pipeline.gltf_compact`` ("none": float32 and uint32)."""
    if compression not in get_args(Compression):
        raise ValueError(f"compression must be one of {get_args(Compression)}, got {compression!r}")
    layers = [layer if isinstance(layer, GltfLayer) else GltfLayer(*layer) for layer in layers]
    if not layers:
        raise ValueError("layers must not be empty")
    out = _Writer(len(layers))
    gltf = out.gltf
    images: dict[str, int] = {}  # sha256 of the PNG -> texture index

    def texture(png: bytes) -> int:
        key = hashlib.sha256(png).hexdigest()
        if key not in images:
            gltf.setdefault("samplers", [REPEAT_SAMPLER])
            gltf.setdefault("images", []).append({"bufferView": out.view(png, None), "mimeType": "image/png"})
            gltf.setdefault("textures", []).append({"sampler": 0, "source": len(gltf["images"]) - 1})
            images[key] = len(gltf["textures"]) - 1
        return images[key]

    transformed = False
    for i, layer in enumerate(layers):
        name = layer.name
        v = np.asarray(layer.vertices, dtype=np.float64)
        f = np.asarray(layer.faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or not np.all(np.isfinite(v)):
            raise ValueError(f"layer {name!r}: vertices must be finite (V, 3)")
        colors = None if layer.colors is None else np.asarray(layer.colors, dtype=np.float32)
        if colors is not None:
            if colors.shape != v.shape or compression != "none":
                raise ValueError(f"layer {name!r}: colors must be (V, 3), in the plain encoding only")
            layer = GltfLayer(name, v, f, extras=layer.extras)
        if layer.display is not None:
            layer.display.check(len(v), f)
        normals = (vertex_normals(v, f) @ ANNY_TO_GLTF.T).astype(np.float32)
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        faces, uv = f, None
        if layer.display is not None:
            (v, normals), faces = layer.display.place(v, f, normals), layer.display.faces
            normals, uv = normals.astype(np.float32), layer.display.uv
        node, uv_transform = {"name": name, "mesh": i}, None
        if layer.extras:
            node["extras"] = layer.extras
        if compression == "none":
            attributes = {
                "POSITION": out.add((v @ ANNY_TO_GLTF.T).astype(np.float32), 34962, 5126, "VEC3", True),
                "NORMAL": out.add(normals, 34962, 5126, "VEC3", False),
            }
            if uv is not None:
                attributes["TEXCOORD_0"] = out.add(uv.astype(np.float32), 34962, 5126, "VEC2", False)
            if colors is not None:
                attributes["COLOR_0"] = out.add(colors, 34962, 5126, "VEC3", False)
            idx = out.add(np.asarray(faces).astype(np.uint32).reshape(-1), 34963, 5125, "SCALAR", False)
        else:
            textured = layer.material is not None and bool(layer.material.textures)
            compact = gltf_compact.compact_layer(v @ ANNY_TO_GLTF.T, normals, uv, faces, textured)
            if compression == "meshopt":
                compact = gltf_compact.reordered(compact)
            attributes, idx = gltf_compact.write_primitive(out, compact, compression == "meshopt")
            p = compact.positions
            node |= {"translation": p.translation.tolist(), "scale": [p.scale] * 3}
            if compact.uv is not None and not compact.uv.identity:
                uv_transform = {TEXTURE_TRANSFORM: gltf_compact.texture_transform(compact.uv)}
                transformed = True
        textures = texture if layer.display is not None else None
        material = _material(name, layer.material, textures, uv_transform)
        if colors is not None:  # COLOR_0 multiplies the base colour: white shows the map as it is
            material["pbrMetallicRoughness"]["baseColorFactor"] = [1.0, 1.0, 1.0, 1.0]
        gltf["materials"].append(material)
        primitive = {"attributes": attributes, "indices": idx, "material": i, "mode": 4}
        gltf["meshes"].append({"name": name, "primitives": [primitive]})
        gltf["nodes"].append(node)
    extensions = {"none": [], "quantized": [QUANTIZATION], "meshopt": [QUANTIZATION, MESHOPT]}[compression]
    return out.glb(extensions + ([TEXTURE_TRANSFORM] if transformed else []))


def _material(name: str, material: Material | None, texture, extensions: dict | None = None) -> dict:
    """The glTF material of a layer; ``texture(png) -> index`` embeds an image (None: no UVs, so no
    textures); ``extensions`` go on each textureInfo (the UV dequantization)."""
    color = (*COLORS.get(name, (0.6, 0.6, 0.6)), 1.0) if material is None else material.base_color
    pbr = {"baseColorFactor": [*color], "metallicFactor": 0.0,
           "roughnessFactor": 0.9 if material is None else material.roughness}  # fmt: skip
    out = {"name": name, "doubleSided": name != "body", "pbrMetallicRoughness": pbr}
    if material is not None and texture is not None:
        more = {"extensions": extensions} if extensions else {}
        if "base_color" in material.textures:
            pbr["baseColorTexture"] = {"index": texture(material.textures["base_color"])} | more
        if "normal" in material.textures:
            out["normalTexture"] = {"index": texture(material.textures["normal"])} | more
    return out
