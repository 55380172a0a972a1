"""What depends only on a mesh's faces (rings, edges, rims), kept per face array, and the
angle-weighted pseudo-normals that sign closest-point distances (numpy only).

Split from ``service.geometry.closest``, which uses them for every query.
"""

from __future__ import annotations

import hashlib
import threading
import weakref
from dataclasses import dataclass

import numpy as np


def _sum_into(index: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """``out (n, 3)`` with ``out[index[i]] += values[i]`` in order: ``np.add.at`` bit for bit (both add
    in input order from zero), ~10x faster."""
    return np.stack([np.bincount(index, weights=values[:, d], minlength=n) for d in range(3)], axis=1)


def _unique_edges(lo: np.ndarray, hi: np.ndarray, n_v: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(lo * n_v + hi, return_inverse=True)`` for edges ``lo <= hi (E,)`` of a mesh with
    ``n_v`` vertices: by two stable 16-bit passes (numpy radix-sorts 16-bit keys), ~2x faster."""
    keys = lo * n_v + hi
    if n_v > 1 << 16:
        return np.unique(keys, return_inverse=True)
    order = np.argsort(hi.astype(np.uint16), kind="stable")
    order = order[np.argsort(lo[order].astype(np.uint16), kind="stable")]
    ranked = keys[order]
    first = np.ones(len(keys), dtype=bool)
    first[1:] = ranked[1:] != ranked[:-1]
    inverse = np.empty(len(keys), dtype=np.int64)
    inverse[order] = np.cumsum(first) - 1
    return ranked[first], inverse


@dataclass
class PseudoNormals:
    """Angle-weighted pseudo-normals (Baerentzen and Aanaes 2005) of a mesh's vertices and edges.

    The sign of (x - p) . n at the closest point p is only right for the normal of the feature p
    lies on: a face's normal inside it, the sum of the two face normals on an edge, the
    angle-weighted vertex normal at a vertex. The face normal alone flips signs in concave places.
    """

    vertex: np.ndarray  # (V, 3)
    edge_keys: np.ndarray  # (E,) sorted keys lo * V + hi
    edge: np.ndarray  # (E, 3)
    edge_faces: np.ndarray  # (E,) int, how many triangles hold each edge

    @classmethod
    def build(cls, vertices: np.ndarray, faces: np.ndarray, fn: np.ndarray) -> PseudoNormals:
        n_v = len(vertices)
        corner = np.take(vertices, faces, axis=0)  # (F, 3, 3)
        weighted = []
        for k in range(3):
            a = corner[:, (k + 1) % 3] - corner[:, k]
            b = corner[:, (k + 2) % 3] - corner[:, k]
            # |a| as np.linalg.norm sums it, bit for bit, in a third of the time; the dot product
            # stays einsum's (its rounding differs from a sum of products).
            length = [np.sqrt(u[:, 0] * u[:, 0] + u[:, 1] * u[:, 1] + u[:, 2] * u[:, 2]) for u in (a, b)]
            cos = np.einsum("fd,fd->f", a, b) / np.maximum(length[0] * length[1], 1e-300)
            weighted.append(np.arccos(np.clip(cos, -1, 1))[:, None] * fn)
        vertex = _sum_into(faces.T.reshape(-1), np.concatenate(weighted), n_v)
        e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        edge_keys, inverse = _unique_edges(np.minimum(e[:, 0], e[:, 1]), np.maximum(e[:, 0], e[:, 1]), n_v)
        edge = _sum_into(inverse, np.tile(fn, (3, 1)), len(edge_keys))
        return cls(vertex, edge_keys, edge, np.bincount(inverse, minlength=len(edge_keys)))

    def at(self, faces: np.ndarray, face: np.ndarray, bary: np.ndarray, fn: np.ndarray) -> np.ndarray:
        """Pseudo-normals ``(N, 3)`` (not unit) at closest points given by ``face (N,)``, ``bary (N, 3)``."""
        zero = bary <= 1e-12
        n_zero = zero.sum(axis=1)
        out = fn[face].copy()
        tri = faces[face]
        vert = n_zero == 2
        if vert.any():
            out[vert] = self.vertex_at(tri[vert][~zero[vert]])
        edge = n_zero == 1
        if edge.any():
            ends = tri[edge][~zero[edge]].reshape(-1, 2)
            n_v = len(self.vertex)
            keys = ends.min(axis=1) * n_v + ends.max(axis=1)
            pos = np.clip(np.searchsorted(self.edge_keys, keys), 0, len(self.edge_keys) - 1)
            out[edge] = np.where((self.edge_keys[pos] == keys)[:, None], self.edge_at(pos), out[edge])
        return out

    def vertex_at(self, index: np.ndarray) -> np.ndarray:
        """Pseudo-normals ``(N, 3)`` of vertices ``index (N,)``."""
        return self.vertex[index]

    def ready(self, vertices: np.ndarray, edges: np.ndarray) -> None:
        """Make sure ``vertex`` holds the rows ``vertices (N,)`` and ``edge`` the rows ``edges (M,)``
        (all of them are, here)."""

    def edge_at(self, index: np.ndarray) -> np.ndarray:
        """Pseudo-normals ``(N, 3)`` of edges ``index (N,)`` (rows of ``edge_keys``)."""
        return self.edge[index]


def _padded(
    owner: np.ndarray, values: np.ndarray, n: int, stable_keys: np.ndarray | None = None
) -> np.ndarray:
    """``(n, R)`` rows: ``values`` grouped by ``owner (M,)`` in input order, padded with -1."""
    keys = owner if stable_keys is None else stable_keys
    order = np.argsort(keys, kind="stable")
    count = np.bincount(owner, minlength=n)
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    out = np.full((n, max(int(count.max(initial=0)), 1)), -1, dtype=np.int64)
    out[owner[order], np.arange(len(owner)) - np.repeat(start, count)] = values[order]
    return out


@dataclass
class MeshTopology:
    """What ``ClosestPoint`` needs from a mesh's faces alone: a garment's (or the body's) faces never
    change, and the squeeze and the repair build a ``ClosestPoint`` for every new mesh of it
    (``mesh_topology`` keeps one per face array)."""

    ring: np.ndarray  # (V, R) int64 faces around each vertex in increasing order, -1 padded
    corners: np.ndarray  # (V, C) int64 corners k F + f of each vertex, in PseudoNormals.build's order
    edge_keys: np.ndarray  # (E,) int64 sorted keys lo * V + hi
    edge_sides: np.ndarray  # (E, S) int64 faces of each edge, in PseudoNormals.build's order, -1 padded
    edge_faces: np.ndarray  # (E,) int64 how many triangles hold each edge
    boundary_edges: np.ndarray  # (B,) int64 sorted keys of the edges with one triangle
    boundary_vertices: np.ndarray  # (V,) bool the ends of the boundary edges
    tree: tuple | None = None
    """``service.geometry.bvh_kernel.build``'s tree of these faces (left, start, count, order), filled
    by ``ClosestPoint`` on its first query of a mesh with them: it holds for any vertex positions."""

    @classmethod
    def build(cls, faces: np.ndarray, n_v: int) -> MeshTopology:
        """From ``faces (F, 3) int64`` over ``n_v`` vertices."""
        n_f = len(faces)
        owner = faces.reshape(-1)
        # Stable, so the same order from 16-bit keys, which numpy radix-sorts (~3x faster).
        small = owner.astype(np.uint16) if n_v <= 1 << 16 else owner
        ring = _padded(owner, np.arange(len(owner)) // 3, n_v, small)
        # PseudoNormals.build sums a vertex's corners in the order of faces.T.reshape(-1), an edge's
        # faces in the order of its edge list (edges 01 of all faces, then 12, then 20).
        by_corner = faces.T.reshape(-1)
        small = by_corner.astype(np.uint16) if n_v <= 1 << 16 else by_corner
        corners = _padded(by_corner, np.arange(len(by_corner)), n_v, small)
        e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        edge_keys, inverse = _unique_edges(np.minimum(e[:, 0], e[:, 1]), np.maximum(e[:, 0], e[:, 1]), n_v)
        edge_sides = _padded(inverse, np.arange(len(inverse)) % max(n_f, 1), len(edge_keys))
        edge_faces = np.bincount(inverse, minlength=len(edge_keys))
        boundary = edge_keys[edge_faces == 1]
        rim = np.zeros(n_v, dtype=bool)
        rim[boundary // n_v] = True
        rim[boundary % n_v] = True
        return cls(ring, corners, edge_keys, edge_sides, edge_faces, boundary, rim)


def mesh_topology(faces: np.ndarray, n_v: int) -> MeshTopology:
    """``MeshTopology.build``, kept per distinct face array (by content) and vertex count, as
    ``service.pipeline.fit.vertex_neighbours`` keeps the adjacency (shared: do not modify it)."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    key = (n_v, faces.shape, faces_key(faces))
    with _TOPOLOGY_LOCK:
        found = _TOPOLOGY.get(key)
    if found is None:
        found = MeshTopology.build(faces, n_v)
        with _TOPOLOGY_LOCK:
            while len(_TOPOLOGY) >= TOPOLOGY_CACHE:
                _TOPOLOGY.pop(next(iter(_TOPOLOGY)))  # the oldest
            _TOPOLOGY[key] = found
    return found


def faces_key(faces: np.ndarray) -> bytes:
    """The sha1 of an int64 face array's bytes: the key of the caches kept per distinct face array.

    A read-only array (the catalog's garments and the body, ``frozen``) cannot change, so its digest
    is kept for as long as the array lives, by identity: every request asks for the keys of the same
    arrays several times (fit, squeeze, repair; ~0.4 ms each for a jacket)."""
    if faces.flags.writeable or faces.base is not None:
        return hashlib.sha1(np.ascontiguousarray(faces, dtype=np.int64).tobytes()).digest()
    ident = id(faces)
    with _TOPOLOGY_LOCK:
        kept = _DIGESTS.get(ident)
    if kept is not None and kept[0]() is faces:
        return kept[1]
    digest = hashlib.sha1(np.ascontiguousarray(faces, dtype=np.int64).tobytes()).digest()
    ref = weakref.ref(faces, lambda _, i=ident: _DIGESTS.pop(i, None))
    with _TOPOLOGY_LOCK:
        _DIGESTS[ident] = (ref, digest)
    return digest


def frozen(array: np.ndarray) -> np.ndarray:
    """``array``, made read-only (shared for the process's life: never modified in place)."""
    array.flags.writeable = False
    return array


_DIGESTS: dict = {}
TOPOLOGY_CACHE = 32  # face arrays kept: the body, the catalog's garments and a few more
_TOPOLOGY: dict = {}
_TOPOLOGY_LOCK = threading.Lock()


def _corner_angles(vertices: np.ndarray, faces: np.ndarray, corner: np.ndarray) -> np.ndarray:
    """Angles ``(M,)`` at corners ``corner (M,)`` (k F + f: corner k of face f), as PseudoNormals.build
    computes them (the same operations on the same values, so the same bits)."""
    f, k = corner % len(faces), corner // len(faces)
    tri = faces[f]
    rows = np.arange(len(f))
    at = np.take(vertices, tri[rows, k], axis=0)
    a = np.take(vertices, tri[rows, (k + 1) % 3], axis=0) - at
    b = np.take(vertices, tri[rows, (k + 2) % 3], axis=0) - at
    length = [np.sqrt(u[:, 0] * u[:, 0] + u[:, 1] * u[:, 1] + u[:, 2] * u[:, 2]) for u in (a, b)]
    cos = np.einsum("fd,fd->f", a, b) / np.maximum(length[0] * length[1], 1e-300)
    return np.arccos(np.clip(cos, -1, 1))


def _sum_rows(values: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``(N, 3)`` sums of ``values[index[n, r]]`` over r in order from zero, -1 entries skipped:
    ``_sum_into``'s sums, which add in input order from zero too."""
    out = np.zeros((len(index), 3))
    for r in range(index.shape[1]):
        col = index[:, r]
        some = np.flatnonzero(col >= 0)
        out[some] += values[col[some]]
    return out


class LazyPseudoNormals(PseudoNormals):
    """``PseudoNormals.build``'s normals, each vertex's and edge's computed the first time ``at`` needs
    it, bit for bit (the same terms summed in the same order): a query reaches a few thousand of a
    body's 13,000 vertices, and the angles of all its corners were most of building a mesh's
    structures. ``vertex`` and ``edge`` hold only those computed so far."""

    @classmethod
    def of(cls, vertices: np.ndarray, faces: np.ndarray, fn: np.ndarray, topology: MeshTopology):
        out = cls(np.zeros((len(vertices), 3)), topology.edge_keys, np.zeros((len(topology.edge_keys), 3)),
                  topology.edge_faces)  # fmt: skip
        out._mesh, out._topology = (vertices, faces, fn), topology
        out._vertex_done = np.zeros(len(vertices), dtype=bool)
        out._edge_done = np.zeros(len(topology.edge_keys), dtype=bool)
        out._lock = threading.Lock()  # the query's threads may ask for the same normals
        return out

    def ready(self, vertices: np.ndarray, edges: np.ndarray) -> None:
        if len(vertices) and not self._vertex_done[vertices].all():
            self.vertex_at(vertices)
        if len(edges) and not self._edge_done[edges].all():
            self.edge_at(edges)

    def vertex_at(self, index: np.ndarray) -> np.ndarray:
        with self._lock:
            todo = np.unique(index[~self._vertex_done[index]])
            if len(todo):
                vertices, faces, fn = self._mesh
                corners = self._topology.corners[todo]  # (T, C)
                valid = corners >= 0
                weighted = np.zeros(corners.shape + (3,))
                used = corners[valid]
                weighted[valid] = _corner_angles(vertices, faces, used)[:, None] * fn[used % len(faces)]
                out = np.zeros((len(todo), 3))
                for r in range(corners.shape[1]):
                    out += weighted[:, r]  # + 0.0 at the padding: no change
                self.vertex[todo] = out
                self._vertex_done[todo] = True
            return self.vertex[index]

    def edge_at(self, index: np.ndarray) -> np.ndarray:
        with self._lock:
            todo = np.unique(index[~self._edge_done[index]])
            if len(todo):
                self.edge[todo] = _sum_rows(self._mesh[2], self._topology.edge_sides[todo])
                self._edge_done[todo] = True
            return self.edge[index]
