"""meshoptimizer's encoder and decoder (the official WebAssembly builds) run by ``wasmtime``.

The npm package ``meshoptimizer`` (1.3.0, MIT; ``vendor/``, unchanged, with its licence) ships
``meshopt_encoder.js`` and ``meshopt_decoder.js`` whose wasm modules are embedded as packed strings
and instantiated with no imports; ``unpack`` is their ``unpack``, ported. The PyPI ``meshoptimizer``
package would need a compiler at install (it has no wheels); ``wasmtime`` is a manylinux wheel.

What ``EXT_meshopt_compression`` needs (vertex codec version 0, header 0xa0, as the extension
specifies; index codec version 1, header 0xe1): ``encode_attributes``, ``encode_triangles``,
``encode_filter_oct``, ``reorder`` (vertex cache then vertex fetch order) and ``decode``, the
official decoder, which ``service.pipeline.gltf_read`` uses and the tests hold against the npm
package's JavaScript decoder run by node. One wasm instance per thread (a wasmtime store is not
thread-safe); each call frees what it allocated.
"""

from __future__ import annotations

import re
import threading
from contextlib import contextmanager
from functools import cache
from pathlib import Path
from typing import Literal

import numpy as np

VENDOR = Path(__file__).parent / "vendor"
ENCODER_JS = VENDOR / "meshopt_encoder.js"
DECODER_JS = VENDOR / "meshopt_decoder.js"
VERTEX_VERSION = 0  # EXT_meshopt_compression's vertex codec (version 1 is KHR_meshopt_compression's)
VERTEX_LEVEL = 2  # what the npm encoder's encodeGltfBuffer uses
Mode = Literal["ATTRIBUTES", "TRIANGLES", "INDICES"]
Filter = Literal["NONE", "OCTAHEDRAL"]


def unpack(data: str, table: list[int]) -> bytes:
    """The wasm bytes of a packed string of the npm files: each character a 6-bit code; codes below 60
    stand for ``table[code]``, a code c >= 60 and the next one n for the byte (c - 60) * 64 + n."""
    c = np.frombuffer(data.encode("ascii"), np.uint8).astype(np.int64)
    codes = np.where(c > 96, c - 97, np.where(c > 64, c - 39, c + 4)).tolist()
    out, i = bytearray(), 0
    while i < len(codes):
        if codes[i] < 60:
            out.append(table[codes[i]])
        else:
            i += 1
            out.append(((codes[i - 1] - 60) * 64 + codes[i]) & 255)
        i += 1
    return bytes(out)


@cache
def _module(path: Path, variable: str):
    import wasmtime

    text = path.read_text()
    packed = re.search(variable + r" =\s*'([^']*)'", text)
    table = re.search(r"wasmpack = new Uint8Array\(\[([^\]]*)\]", text)
    if packed is None or table is None:
        raise RuntimeError(f"{path.name}: no packed wasm {variable!r} found")
    engine = wasmtime.Engine()
    wasm = unpack(packed.group(1), [int(x) for x in table.group(1).split(",") if x.strip()])
    return engine, wasmtime.Module(engine, wasm)


class _Wasm:
    """One instance of a module with its store: ``call(name, *ints)``, and heap helpers over sbrk."""

    def __init__(self, path: Path, variable: str):
        import wasmtime

        engine, module = _module(path, variable)
        self.store = wasmtime.Store(engine)
        self.instance = wasmtime.Instance(self.store, module, [])
        self.exports = self.instance.exports(self.store)
        self.memory = self.exports["memory"]
        self.call("__wasm_call_ctors")

    def call(self, name: str, *args: int) -> int:
        return self.exports[name](self.store, *args)

    def put(self, data: bytes) -> int:
        ptr = self.call("sbrk", len(data))
        self.memory.write(self.store, data, ptr)
        return ptr

    def get(self, ptr: int, size: int) -> bytes:
        return bytes(self.memory.read(self.store, ptr, ptr + size))

    def free(self, ptr: int) -> None:
        """Release everything allocated since ``ptr`` (the npm files' ``sbrk(ptr - sbrk(0))``)."""
        self.call("sbrk", ptr - self.call("sbrk", 0))


_local = threading.local()


@contextmanager
def _heap(kind: str):
    """The thread's encoder or decoder instance; what it allocates inside the block is freed after."""
    if not hasattr(_local, kind):
        if kind == "encoder":
            wasm = _Wasm(ENCODER_JS, "wasm")
            wasm.call("meshopt_encodeIndexVersion", 1)
        else:
            wasm = _Wasm(DECODER_JS, "wasm_base")
        setattr(_local, kind, wasm)
    wasm = getattr(_local, kind)
    top = wasm.call("sbrk", 0)
    try:
        yield wasm
    finally:
        wasm.free(top)


def _rows(data: np.ndarray) -> np.ndarray:
    data = np.ascontiguousarray(data)
    if data.ndim != 2 or data.dtype.itemsize * data.shape[1] % 4 or not 0 < data.nbytes // len(data) <= 256:
        raise ValueError(f"vertex data must be (count, k) rows of 4..256 bytes, 4 | bytes: {data.shape}")
    return data


def encode_attributes(data: np.ndarray) -> bytes:
    """The vertex codec's stream (ATTRIBUTES mode) of ``data (count, k)``, rows of 4..256 bytes."""
    data = _rows(data)
    count, size = len(data), data.nbytes // len(data)
    with _heap("encoder") as w:
        bound = w.call("meshopt_encodeVertexBufferBound", count, size)
        out = w.call("sbrk", bound)
        src = w.put(data.tobytes())
        args = (out, bound, src, count, size, VERTEX_LEVEL, VERTEX_VERSION)
        n = w.call("meshopt_encodeVertexBufferLevel", *args)
        if n == 0:
            raise RuntimeError("meshopt vertex encoder failed")
        return w.get(out, n)


def encode_triangles(indices: np.ndarray, vertex_count: int) -> bytes:
    """The index codec's stream (TRIANGLES mode) of ``indices (3F,)`` below ``vertex_count``."""
    indices = np.ascontiguousarray(indices, dtype=np.uint32).reshape(-1)
    if len(indices) % 3 or (len(indices) and int(indices.max()) >= vertex_count):
        raise ValueError("indices must be 3F vertex indices below vertex_count")
    with _heap("encoder") as w:
        bound = w.call("meshopt_encodeIndexBufferBound", len(indices), vertex_count)
        out = w.call("sbrk", bound)
        src = w.put(indices.tobytes())
        n = w.call("meshopt_encodeIndexBuffer", out, bound, src, len(indices))
        if n == 0:
            raise RuntimeError("meshopt index encoder failed")
        return w.get(out, n)


def encode_filter_oct(normals: np.ndarray, bits: int = 8) -> np.ndarray:
    """Unit ``normals (V, 3)`` as the OCTAHEDRAL filter's input (V, 4) int8 (bits <= 8) or int16."""
    normals = np.asarray(normals, dtype=np.float32)
    if normals.ndim != 2 or normals.shape[1] != 3 or not 2 <= bits <= 16:
        raise ValueError(f"normals must be (V, 3) and bits in 2..16, got {normals.shape}, {bits}")
    dtype = np.int8 if bits <= 8 else np.int16
    stride = 4 * dtype().itemsize
    source = np.concatenate([normals, np.zeros((len(normals), 1), np.float32)], axis=1)
    with _heap("encoder") as w:
        out = w.call("sbrk", len(normals) * stride)
        src = w.put(source.tobytes())
        w.call("meshopt_encodeFilterOct", out, len(normals), stride, bits, src)
        return np.frombuffer(w.get(out, len(normals) * stride), dtype).reshape(-1, 4)


def reorder(indices: np.ndarray, vertex_count: int) -> tuple[np.ndarray, np.ndarray]:
    """meshopt's vertex cache order of the triangles, then vertex fetch order of the vertices:
    (remap (V,) old vertex -> new, indices (3F,) into the new order). The triangles are the same;
    vertices of no triangle go last."""
    indices = np.ascontiguousarray(indices, dtype=np.uint32).reshape(-1)
    n = len(indices)
    if n and int(indices.max()) >= vertex_count:
        raise ValueError("indices must be below vertex_count")
    with _heap("encoder") as w:
        ip = w.put(indices.tobytes())
        rp = w.call("sbrk", vertex_count * 4)
        w.call("meshopt_optimizeVertexCache", ip, ip, n, vertex_count)
        unique = w.call("meshopt_optimizeVertexFetchRemap", rp, ip, n, vertex_count)
        remap = np.frombuffer(w.get(rp, vertex_count * 4), np.uint32).astype(np.int64)
        cached = np.frombuffer(w.get(ip, n * 4), np.uint32).astype(np.int64)
    unused = remap == 0xFFFFFFFF  # vertices of no triangle: kept, after the others
    remap[unused] = unique + np.arange(int(unused.sum()))
    return remap, remap[cached]


def decode(encoded: bytes, count: int, stride: int, mode: Mode, filter: Filter = "NONE") -> bytes:
    """The official decoder's ``decodeGltfBuffer``: ``count`` elements of ``stride`` bytes."""
    fun = {"ATTRIBUTES": "meshopt_decodeVertexBuffer", "TRIANGLES": "meshopt_decodeIndexBuffer",
           "INDICES": "meshopt_decodeIndexSequence"}[mode]  # fmt: skip
    with _heap("decoder") as w:
        count4 = (count + 3) & ~3  # the filters work on groups of 4 (as in the npm file's decode)
        out = w.call("sbrk", count4 * stride)
        src = w.put(bytes(encoded))
        result = w.call(fun, out, count, stride, src, len(encoded))
        if result != 0:
            raise ValueError(f"malformed meshopt buffer data: {result}")
        if filter == "OCTAHEDRAL":
            w.call("meshopt_decodeFilterOct", out, count4, stride)
        return w.get(out, count * stride)
