"""Compact encodings of a GLB layer: ``KHR_mesh_quantization``, and ``EXT_meshopt_compression`` over it.

Quantized (what ``service.pipeline.gltf.outfit_glb`` writes for ``compression="quantized"``):

- POSITION: int16 normalized, per layer centred on its bounding box and divided by its largest
  half-extent; the node's translation and UNIFORM scale undo that (a uniform scale keeps normals
  normal). A body 1.8 m tall rounds to a 27 um grid, each coordinate within 14 um of the float; on
  the outfits of ``benchmarks.outfits`` on 3 bodies the decoded layers cross nowhere and penetrate
  as much as the floats (``python -m benchmarks.glb_sizes --all-outfits``). Points the same before
  rounding (UV seams) are the same after.
- NORMAL: int8 normalized (error < 0.5 degree).
- TEXCOORD_0: uint16 normalized. The garments' UVs tile (they run from about -24 to 13), so
  they are mapped onto [0, 1] by their bounds and the material's textures carry the inverse as
  ``KHR_texture_transform`` (offset, scale); UVs already in [0, 1] are stored as they are. A layer
  with UVs outside [0, 1] and no texture keeps float UVs (no texture to carry the transform).
- indices: uint16 where the layer has fewer than 65,535 vertices (65,535 is the restart value).

glTF wants attribute strides of 4 bytes: positions take 8 (x, y, z, 0), normals 4 (x, y, z, 0).

meshopt (``compression="meshopt"``): the same quantized arrays, vertices and triangles first put in
meshopt's vertex cache / vertex fetch order (the same triangles), then each attribute through the
vertex codec (normals octahedral-filtered, 8 bits), the indices through the TRIANGLES index codec
(``service.pipeline.meshopt``). Each compressed view keeps its uncompressed layout in a fallback
buffer with no data, as the extension describes for a required ``EXT_meshopt_compression``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

POSITION_MAX = 32767  # int16 normalized: q / 32767
UV_MAX = 65535  # uint16 normalized
NORMAL_MAX = 127  # int8 normalized
MAX_UINT16_VERTICES = 65535  # indices 0..65534: 65535 is the primitive restart value
# glTF component types
BYTE, UNSIGNED_SHORT, SHORT, UNSIGNED_INT, FLOAT = 5120, 5123, 5122, 5125, 5126


@dataclass(frozen=True)
class QuantizedPositions:
    """values (V, 4) int16 (x, y, z, 0); a point is translation (3,) + scale * values[:, :3] / 32767."""

    values: np.ndarray
    translation: np.ndarray
    scale: float


@dataclass(frozen=True)
class QuantizedUV:
    """values (V, 2) uint16; a texture coordinate is offset (2,) + scale (2,) * values / 65535
    (identity offset 0, scale 1: the UVs were in [0, 1])."""

    values: np.ndarray
    offset: np.ndarray
    scale: np.ndarray

    @property
    def identity(self) -> bool:
        return bool(np.all(self.offset == 0) and np.all(self.scale == 1))


def quantize_positions(positions: np.ndarray) -> QuantizedPositions:
    """``positions (V, 3)`` float (glTF frame) on the int16 grid of their bounding box."""
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or not len(p):
        raise ValueError(f"positions must be (V, 3) with V > 0, got {p.shape}")
    lo, hi = p.min(axis=0), p.max(axis=0)
    centre = (lo + hi) / 2
    scale = max(float((hi - lo).max()) / 2, 1e-6)
    q = np.rint((p - centre) / scale * POSITION_MAX).clip(-POSITION_MAX, POSITION_MAX)
    values = np.zeros((len(p), 4), np.int16)
    values[:, :3] = q
    return QuantizedPositions(values, centre, scale)


def quantize_normals(normals: np.ndarray) -> np.ndarray:
    """Unit ``normals (V, 3)`` as (V, 4) int8 (x, y, z, 0), each component round(127 n)."""
    n = np.asarray(normals, dtype=np.float64)
    if n.ndim != 2 or n.shape[1] != 3:
        raise ValueError(f"normals must be (V, 3), got {n.shape}")
    values = np.zeros((len(n), 4), np.int8)
    values[:, :3] = np.rint(n * NORMAL_MAX).clip(-NORMAL_MAX, NORMAL_MAX)
    return values


def quantize_uv(uv: np.ndarray, remap: bool) -> QuantizedUV | None:
    """``uv (V, 2)`` as uint16: as they are when in [0, 1], else (``remap``) over their bounds; None
    when neither (outside [0, 1] and no texture transform to undo a remapping)."""
    uv = np.asarray(uv, dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv must be (V, 2), got {uv.shape}")
    if not len(uv) or (uv.min() >= 0 and uv.max() <= 1):
        offset, scale = np.zeros(2), np.ones(2)
    elif remap:
        offset = uv.min(axis=0)
        scale = np.maximum(uv.max(axis=0) - offset, 1e-6)
    else:
        return None
    values = np.rint((uv - offset) / scale * UV_MAX).clip(0, UV_MAX).astype(np.uint16)
    return QuantizedUV(values, offset, scale)


def texture_transform(uv: QuantizedUV) -> dict:
    """The ``KHR_texture_transform`` of a textureInfo that reads ``uv``'s stored coordinates."""
    return {"offset": uv.offset.tolist(), "scale": uv.scale.tolist()}


@dataclass(frozen=True)
class CompactLayer:
    """One layer's quantized arrays: positions, normals (V, 4) int8 (and unit_normals (V, 3) float32,
    what meshopt's octahedral filter encodes), uv (or float (V, 2) uv_float, or neither), indices (3F,)
    uint16 or uint32."""

    positions: QuantizedPositions
    normals: np.ndarray
    unit_normals: np.ndarray
    uv: QuantizedUV | None
    uv_float: np.ndarray | None
    indices: np.ndarray


def compact_layer(
    positions: np.ndarray, normals: np.ndarray, uv: np.ndarray | None, faces: np.ndarray, textured: bool
) -> CompactLayer:
    """Quantize a layer: ``positions (V, 3)`` (glTF frame), unit ``normals (V, 3)``, ``uv (V, 2)`` or
    None, ``faces (F, 3)``; ``textured``: its material has a texture to carry a UV transform."""
    q_uv = None if uv is None else quantize_uv(uv, remap=textured)
    uv_float = None if uv is None or q_uv is not None else np.asarray(uv, np.float32)
    dtype = np.uint16 if len(positions) < MAX_UINT16_VERTICES else np.uint32
    return CompactLayer(
        quantize_positions(positions), quantize_normals(normals), np.asarray(normals, np.float32),
        q_uv, uv_float, np.asarray(faces).reshape(-1).astype(dtype),
    )  # fmt: skip


def reordered(layer: CompactLayer) -> CompactLayer:
    """``layer`` in meshopt's vertex cache / fetch order: the same vertices and triangles."""
    from service.pipeline import meshopt

    remap, indices = meshopt.reorder(layer.indices, len(layer.normals))
    order = np.empty_like(remap)
    order[remap] = np.arange(len(remap))  # new vertex -> old

    def take(a):
        return None if a is None else a[order]

    p, uv = layer.positions, layer.uv
    return CompactLayer(
        QuantizedPositions(p.values[order], p.translation, p.scale),
        layer.normals[order], layer.unit_normals[order],
        None if uv is None else QuantizedUV(uv.values[order], uv.offset, uv.scale), take(layer.uv_float),
        indices.astype(layer.indices.dtype),
    )  # fmt: skip


def write_primitive(out, layer: CompactLayer, meshopt: bool, oct_normals: bool = True) -> tuple[dict, int]:
    """Write ``layer``'s views and accessors through ``out`` (``service.pipeline.gltf``'s writer:
    ``view``, ``meshopt_view``, ``accessor``); returns (attributes, index accessor)."""
    from service.pipeline import meshopt as codec

    def put(values, target, component, kind, normalized, bounds=False, normals=None):
        count = len(values)
        raw = np.ascontiguousarray(values)
        if target == 34963:  # indices: no stride
            view = (out.meshopt_view(raw.nbytes, codec.encode_triangles(raw, len(layer.normals)), target,
                                     raw.itemsize, count, "TRIANGLES")
                    if meshopt else out.view(raw.tobytes(), target))  # fmt: skip
            return out.accessor(view, component, count, "SCALAR")
        stride = raw.nbytes // count
        if not meshopt:
            view = out.view(raw.tobytes(), target, stride)
        elif normals is not None:
            filtered = codec.encode_filter_oct(normals, 8)
            view = out.meshopt_view(raw.nbytes, codec.encode_attributes(filtered), target, stride, count,
                                    "ATTRIBUTES", "OCTAHEDRAL")  # fmt: skip
        else:
            encoded = codec.encode_attributes(raw.view(np.uint8).reshape(count, -1))
            view = out.meshopt_view(raw.nbytes, encoded, target, stride, count, "ATTRIBUTES")
        width = {"VEC2": 2, "VEC3": 3}[kind]
        used = raw[:, :width]  # without the padding
        minmax = (used.min(axis=0).tolist(), used.max(axis=0).tolist()) if bounds else None
        return out.accessor(view, component, count, kind, normalized, minmax)

    attributes = {
        "POSITION": put(layer.positions.values, 34962, SHORT, "VEC3", True, bounds=True),
        "NORMAL": put(layer.normals, 34962, BYTE, "VEC3", True,
                      normals=layer.unit_normals if meshopt and oct_normals else None),
    }  # fmt: skip
    if layer.uv is not None:
        attributes["TEXCOORD_0"] = put(layer.uv.values, 34962, UNSIGNED_SHORT, "VEC2", True)
    elif layer.uv_float is not None:
        attributes["TEXCOORD_0"] = put(layer.uv_float, 34962, FLOAT, "VEC2", False)
    component = UNSIGNED_SHORT if layer.indices.dtype == np.uint16 else UNSIGNED_INT
    return attributes, put(layer.indices, 34963, component, "SCALAR", False)
