"""Exact closest points on a triangle mesh (numpy + scipy only).

Used by the canonical space (closest body point of a garment vertex) and by the drape's body
collisions. ``closest_on_triangles`` is the vectorised point-triangle test (Ericson, Real-Time
Collision Detection 5.1.5); ``ClosestPoint`` restricts it to triangles around the nearest
vertices, and ``closest_point_reference`` checks every triangle. ``ClosestPoint.query`` screens
the candidates with ``DistanceBounds`` (cheap bounds on each squared distance) and runs Ericson's
test only where a bound leaves the winner open; ``ClosestPoint.query_reference`` tests every
candidate, and the two agree bit for bit.
"""

from __future__ import annotations

import hashlib
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

from service.mesh import check_mesh, face_normals


def _check_points(points: np.ndarray) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be (N, 3), got {points.shape}")
    return points


def closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Barycentric coordinates ``(..., 3)`` of the point of triangle abc closest to p.

    All inputs ``(..., 3)`` broadcast together. Degenerate triangles fall back to their edges.
    """
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("...d,...d->...", ab, ap), np.einsum("...d,...d->...", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("...d,...d->...", ab, bp), np.einsum("...d,...d->...", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("...d,...d->...", ab, cp), np.einsum("...d,...d->...", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    shape = np.broadcast_shapes(d1.shape, d3.shape, d5.shape)

    def safe(num, den):
        return num / np.where(np.abs(den) > 1e-30, den, 1e-30)

    # Voronoi regions from the most specific (vertex) to the face; the first that holds wins,
    # so the selection runs backwards with np.where (boolean assignment is ~3x slower).
    one, zero = np.ones(shape), np.zeros(shape)
    den = va + vb + vc
    v, t = safe(vb, den), safe(vc, den)
    w = np.stack([1 - v - t, v, t], axis=-1)
    t = np.clip(safe(d4 - d3, (d4 - d3) + (d5 - d6)), 0, 1)
    w = np.where(
        ((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0))[..., None], np.stack([zero, 1 - t, t], -1), w
    )
    t = np.clip(safe(d2, d2 - d6), 0, 1)
    w = np.where(((vb <= 0) & (d2 >= 0) & (d6 <= 0))[..., None], np.stack([1 - t, zero, t], -1), w)
    t = np.clip(safe(d1, d1 - d3), 0, 1)
    w = np.where(((vc <= 0) & (d1 >= 0) & (d3 <= 0))[..., None], np.stack([1 - t, t, zero], -1), w)
    w = np.where(((d6 >= 0) & (d5 <= d6))[..., None], np.stack([zero, zero, one], -1), w)
    w = np.where(((d3 >= 0) & (d4 <= d3))[..., None], np.stack([zero, one, zero], -1), w)
    w = np.where(((d1 <= 0) & (d2 <= 0))[..., None], np.stack([one, zero, zero], -1), w)
    return w


PAIR_CHUNK = 16384  # (point, triangle) pairs per pass: its ~30 temporaries stay in the cache
BOUND_SLACK = 1e-9  # DistanceBounds' relative width: >1e4 x the rounding seen near the origin


@dataclass
class DistanceBounds:
    """Bounds on the squared distance that ``closest_on_triangles`` gives for a point-triangle pair.

    Per triangle abc it keeps a, e0 = b - a, e1 = c - a and scalars of their Gram matrix, one row per
    scalar (gathering a row per scalar is ~3x faster than a row per triangle). A pair then costs three
    dot products and ~50 operations on ``(M,)`` arrays instead of Ericson's ~150 on ``(M, 3)``: the
    squared distance is that of the plane projection a + s e0 + u e1 when it falls inside the
    triangle, otherwise the least of its three edges' (the closest point of a triangle is on its
    boundary when the projection is not inside).

    The two computations differ by rounding only, which grows with the triangle's condition number
    k = |e0|^2 |e1|^2 / det(Gram) (the solve for s, u) and with coordinates far from the origin
    (both work from differences of absolute coordinates). ``squared_distance`` widens its estimate by
    ``BOUND_SLACK * k * (q + |e0|^2 + |e1|^2) + (1e5 * 64 eps * max |vertex|)^2`` (q = |p - a|^2);
    on 200k random triangles (k up to 1e12, points 1e-8 to 1e5 edge lengths away) the difference
    stayed below 1e-4 of that within 10 m of the origin and below 3e-3 at 100 km. Triangles with
    det(Gram) <= 1e-12 |e0|^2 |e1|^2, where Ericson's own answer drifts, get unbounded bounds
    (always tested, never used to rule others out).
    """

    # (21, F) float64: a, e0, e1 (rows 0-8); g11, g01, g00 over det(Gram) (9-11); 1 / |e0|^2,
    # 1 / |e1|^2, 1 / |c - b|^2 (12-14, 0 for a zero length); |e0|^2, |e1|^2, |c - b|^2, |e0|^2 - e0 . e1
    # (15-18); the width's factor of q and its constant (19-20).
    table: np.ndarray

    @classmethod
    def build(cls, vertices: np.ndarray, faces: np.ndarray) -> DistanceBounds:
        """From a mesh ``vertices (V, 3) float64``, ``faces (F, 3) int``."""
        # In place, row by row: ~10x faster than with np.where and a temporary per row.
        t = np.empty((21, len(faces)))
        for k in range(3):
            for d in range(3):
                np.take(vertices[:, d], faces[:, k], out=t[3 * k + d])
        a, e0, e1 = t[0:3], t[3:6], t[6:9]
        e0 -= a
        e1 -= a
        g00, g11, gbc = t[15], t[16], t[17]
        np.add(e0[0] * e0[0] + e0[1] * e0[1], e0[2] * e0[2], out=g00)
        np.add(e1[0] * e1[0] + e1[1] * e1[1], e1[2] * e1[2], out=g11)
        g01 = e0[0] * e1[0] + e0[1] * e1[1] + e0[2] * e1[2]
        det = g00 * g11 - g01 * g01
        ok = det > 1e-12 * g00 * g11
        inv = np.divide(1.0, det, out=np.zeros(len(faces)), where=ok)
        np.multiply(g11, inv, out=t[9])  # 9-11: (s, u) from ((p - a) . e0, (p - a) . e1)
        np.multiply(g01, inv, out=t[10])
        np.multiply(g00, inv, out=t[11])
        np.subtract(g00, g01, out=t[18])  # (p - b) . (c - b) = (p - a) . (e1 - e0) + this
        np.subtract(g11 + t[18], g01, out=gbc)  # |c - b|^2
        for g, row in ((g00, 12), (g11, 13), (gbc, 14)):  # 0 for an edge of length 0: its start
            t[row] = 0.0
            np.divide(1.0, g, out=t[row], where=g > 0)
        slack = np.multiply(BOUND_SLACK * g00 * g11, inv, out=t[19])
        floor = 1e10 * (64 * np.finfo(np.float64).eps * np.abs(vertices).max(initial=0.0)) ** 2
        np.add(slack * (g00 + g11), floor, out=t[20])
        t[20, ~ok] = np.inf
        return cls(t)

    def squared_distance(
        self, points: np.ndarray, rows: np.ndarray, face: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(lower (M,), upper (M,)) bounds on the squared distance ``closest_on_triangles`` gives for
        ``points[rows] (M, 3)`` and triangles ``face (M,)``."""
        lower, upper = np.empty(len(face)), np.empty(len(face))
        for start in range(0, len(face), PAIR_CHUNK):
            part = slice(start, start + PAIR_CHUNK)
            lower[part], upper[part] = self._squared_distance(points, rows[part], face[part])
        return lower, upper

    def _squared_distance(self, points, rows, face):
        t = self.table

        def at(i):
            return t[i].take(face)

        apx, apy, apz = (points[:, d].take(rows) - at(d) for d in range(3))
        q = apx * apx + apy * apy + apz * apz  # |p - a|^2
        b0 = apx * at(3) + apy * at(4) + apz * at(5)  # (p - a) . e0
        b1 = apx * at(6) + apy * at(7) + apz * at(8)  # (p - a) . e1
        s_b1 = at(10)
        s, u = at(9) * b0 - s_b1 * b1, at(11) * b1 - s_b1 * b0
        inside = (s >= 0) & (u >= 0) & (s + u <= 1)
        g00, g11, gbc = at(15), at(16), at(17)
        # Each edge u + t e from its start: |p - u - t e|^2 = q_u - t (2 b - t |e|^2), t clipped to [0, 1].
        t_ = np.clip(b0 * at(12), 0, 1)
        edge = q - t_ * (2 * b0 - t_ * g00)
        t_ = np.clip(b1 * at(13), 0, 1)
        edge = np.minimum(edge, q - t_ * (2 * b1 - t_ * g11))
        bc = b1 - b0 + at(18)  # (p - b) . (c - b)
        t_ = np.clip(bc * at(14), 0, 1)
        edge = np.minimum(edge, (q - 2 * b0 + g00) - t_ * (2 * bc - t_ * gbc))
        d2 = np.where(inside, q - s * b0 - u * b1, edge)
        width = at(19) * q + at(20)
        return d2 - width, d2 + width


@dataclass
class Closest:
    """Closest mesh points of N query points."""

    face: np.ndarray  # (N,) int, triangle holding the closest point
    bary: np.ndarray  # (N, 3) its barycentric coordinates in that triangle
    point: np.ndarray  # (N, 3) the closest point
    distance: np.ndarray  # (N,) unsigned distance
    signed: np.ndarray  # (N,) signed by the pseudo-normal: negative inside a closed outward mesh
    normal: np.ndarray  # (N, 3) unit normal of that face


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

    def edge_at(self, index: np.ndarray) -> np.ndarray:
        """Pseudo-normals ``(N, 3)`` of edges ``index (N,)`` (rows of ``edge_keys``)."""
        return self.edge[index]


def _padded(owner: np.ndarray, values: np.ndarray, n: int, stable_keys: np.ndarray | None = None) -> np.ndarray:
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
    ``service.fit.vertex_neighbours`` keeps the adjacency (shared: do not modify it)."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    key = (n_v, faces.shape, hashlib.sha1(faces.tobytes()).digest())
    with _TOPOLOGY_LOCK:
        found = _TOPOLOGY.get(key)
    if found is None:
        found = MeshTopology.build(faces, n_v)
        with _TOPOLOGY_LOCK:
            while len(_TOPOLOGY) >= TOPOLOGY_CACHE:
                _TOPOLOGY.pop(next(iter(_TOPOLOGY)))  # the oldest
            _TOPOLOGY[key] = found
    return found


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


def _finish(points, vertices, faces, fn, face, bary, pseudo: PseudoNormals, point=None) -> Closest:
    if point is None:  # else the caller's, computed as here
        point = np.einsum("nk,nkd->nd", bary, vertices[faces[face]])
    diff = points - point
    dist = np.linalg.norm(diff, axis=1)
    side = np.einsum("nd,nd->n", diff, pseudo.at(faces, face, bary, fn))
    sign = np.where(side < 0, -1.0, 1.0)
    return Closest(face, bary, point, dist, sign * dist, fn[face])


def closest_point_reference(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> Closest:
    """Closest points by testing every triangle: O(N F), for tests and tiny meshes."""
    points = _check_points(points)
    check_mesh(vertices, faces)
    tri = vertices[faces]
    w = closest_on_triangles(points[:, None], tri[None, :, 0], tri[None, :, 1], tri[None, :, 2])
    q = np.einsum("nfk,fkd->nfd", w, tri)
    face = np.argmin(np.linalg.norm(points[:, None] - q, axis=2), axis=1)
    fn = face_normals(vertices, faces)
    pseudo = PseudoNormals.build(vertices, faces, fn)
    return _finish(points, vertices, faces, fn, face, w[np.arange(len(points)), face], pseudo)


class ClosestPoint:
    """Closest-point queries against a fixed triangle mesh.

    Candidates are the triangles around the ``k`` nearest vertices: exact whenever the closest
    triangle touches one of them, which holds for the well-shaped meshes used here (checked
    against ``closest_point_reference`` in the tests). The search structures are built on the first
    query: the repair builds one for every layer it returns, and nothing asks the outermost.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.vertices = vertices  # (V, 3) float64
        self.faces = faces  # (F, 3) int64

    @classmethod
    def build(cls, vertices: np.ndarray, faces: np.ndarray) -> ClosestPoint:
        check_mesh(vertices, faces)
        return cls(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64))

    @cached_property
    def topology(self) -> MeshTopology:
        return mesh_topology(self.faces, len(self.vertices))

    @cached_property
    def ring(self) -> np.ndarray:
        """(V, R) faces around each vertex in increasing order, padded with -1 (shared: do not modify)."""
        return self.topology.ring

    @cached_property
    def tree(self) -> cKDTree:
        return cKDTree(self.vertices)

    @cached_property
    def fn(self) -> np.ndarray:
        """(F, 3) unit face normals."""
        return face_normals(self.vertices, self.faces)

    @cached_property
    def pseudo(self) -> PseudoNormals:
        return LazyPseudoNormals.of(self.vertices, self.faces, self.fn, self.topology)

    @cached_property
    def bounds(self) -> DistanceBounds:
        return DistanceBounds.build(self.vertices, self.faces)

    @property
    def boundary_edges(self) -> np.ndarray:
        """Sorted keys ``min * V + max`` of the edges with one triangle (an open mesh's rims)."""
        return self.topology.boundary_edges

    @property
    def boundary_vertices(self) -> np.ndarray:
        """``(V,) bool``: the ends of the boundary edges."""
        return self.topology.boundary_vertices

    def on_boundary(self, c: Closest) -> np.ndarray:
        """``(N,) bool``: closest points ``c`` lying on the mesh's boundary (a rim edge or its ends).

        There the point is past the mesh's edge rather than on one of its sides: the pseudo-normal's
        sign says little (a point below a T-shirt's hem reads as inside it)."""
        zero = c.bary <= 1e-12
        tri = self.faces[c.face]
        n_v = len(self.vertices)
        out = np.zeros(len(c.face), dtype=bool)
        if not len(self.boundary_edges):
            return out
        vert = zero.sum(axis=1) == 2
        out[vert] = self.boundary_vertices[tri[vert][~zero[vert]]]
        edge = zero.sum(axis=1) == 1
        ends = tri[edge][~zero[edge]].reshape(-1, 2)
        keys = ends.min(axis=1) * n_v + ends.max(axis=1)
        pos = np.clip(np.searchsorted(self.boundary_edges, keys), 0, len(self.boundary_edges) - 1)
        out[edge] = self.boundary_edges[pos] == keys
        return out

    def candidates(
        self, points: np.ndarray, k: int = 4, workers: int = -1
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest points of ``points (N, 3)`` on each triangle around their k nearest vertices.

        Returns (faces (N, C) int, bary (N, C, 3), distance (N, C)), padding slots at +inf distance.
        """
        points = _check_points(points)
        k = min(k, len(self.vertices))
        _, near = self.tree.query(points, k=k, workers=workers)
        near = near.reshape(len(points), k)
        cand = self.ring[near].reshape(len(points), -1)  # (N, k R)
        valid = cand >= 0
        cand = np.where(valid, cand, self.ring[near[:, :1], 0])
        # The rings of neighbouring vertices share most triangles (~4x repeats at k = 4): test each
        # (point, triangle) pair once and copy the result to its repeats.
        order = np.argsort(cand, axis=1, kind="stable")
        ranked = np.take_along_axis(cand, order, 1)
        first = np.ones(ranked.shape, dtype=bool)
        first[:, 1:] = ranked[:, 1:] != ranked[:, :-1]
        rows, cols = np.nonzero(first)
        tri = self.vertices[self.faces[ranked[rows, cols]]]  # (M, 3, 3)
        p = points[rows]
        w_unique = closest_on_triangles(p, tri[:, 0], tri[:, 1], tri[:, 2])  # (M, 3)
        d_unique = np.linalg.norm(p - np.einsum("mk,mkd->md", w_unique, tri), axis=1)
        slot = (np.cumsum(first.ravel()) - 1).reshape(first.shape)  # unique pair of each entry
        w, d = np.empty(cand.shape + (3,)), np.empty(cand.shape)
        np.put_along_axis(w, order[:, :, None], w_unique[slot], 1)
        np.put_along_axis(d, order, d_unique[slot], 1)
        return cand, w, np.where(valid, d, np.inf)

    def query(self, points: np.ndarray, k: int = 4) -> Closest:
        """Closest points of ``points (N, 3)`` on the mesh: ``query_reference`` bit for bit, at a third
        of its cost per point.

        Over ``QUERY_BLOCK`` points, blocks run on ``QUERY_THREADS`` threads (numpy and the KD-tree
        release the GIL; each point's answer depends on that point alone, so the result is the same
        bit for bit): the repair's and the squeeze's queries are most of a request's time. The blocks
        are as many as the threads or a multiple, so that none idles at the end, and large: numpy
        calls on short arrays run no faster on two threads than on one (the GIL).
        """
        points = _check_points(points)
        if len(points) <= QUERY_BLOCK or QUERY_THREADS <= 1:
            return self._query_block(points, k)
        # Build the lazy structures here: cached_property is not safe to fill from two threads.
        _ = self.topology, self.ring, self.tree, self.fn, self.pseudo, self.bounds
        rounds = -(-len(points) // (QUERY_BLOCK * QUERY_THREADS))
        blocks = np.array_split(points, rounds * QUERY_THREADS)
        parts = list(_pool().map(lambda b: self._query_block(b, k), blocks))
        return Closest(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(Closest)))

    def query_reference(self, points: np.ndarray, k: int = 4) -> Closest:
        """``query`` by Ericson's test on every candidate triangle (``candidates``), in one block."""
        points = _check_points(points)
        return self._finish(points, *self._select_reference(points, k))

    def _query_block(self, points: np.ndarray, k: int) -> Closest:
        return self._finish(points, *self._select(points, k))

    def _finish(self, points, face, bary, point=None) -> Closest:
        return _finish(points, self.vertices, self.faces, self.fn, face, bary, self.pseudo, point)

    def _select_reference(self, points, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(face (N,), bary (N, 3)): the candidate with the least distance, the first in ring order
        among equals."""
        cand, w, d = self.candidates(points, k, workers=1)
        best = np.argmin(d, axis=1)
        rows = np.arange(len(points))
        return cand[rows, best], w[rows, best]

    def _select(self, points, k: int):
        """``_select_reference`` and the closest points ``(N, 3)`` (or None), with Ericson's test only
        on the candidates whose lower distance bound is within the least upper bound of their
        point's (~1.1 of ~16 per point)."""
        n = len(points)
        k = min(k, len(self.vertices))
        # One KD-tree worker: more never paid on 2 cores (and costs 0.2 ms per call on small
        # queries); the blocks already run on threads (``query``).
        _, near = self.tree.query(points, k=k, workers=1)
        cand = self.ring[near.reshape(n, k)].reshape(n, -1)  # (N, C) in ring order, -1 padded
        width = cand.shape[1]
        # Each distinct (point, triangle) pair once: a sort (~7x faster than argsort) loses the ring
        # order, which only the ties between the finalists need (found again below).
        ranked = np.sort(cand, axis=1)
        first = ranked >= 0
        first[:, 1:] &= ranked[:, 1:] != ranked[:, :-1]
        flat = np.flatnonzero(first)
        rows, face = flat // width, ranked.ravel()[flat]
        if not len(rows):  # no triangle around any point's k vertices (unreferenced vertices)
            return *self._select_reference(points, k), None
        lower, upper = self.bounds.squared_distance(points, rows, face)
        start = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])  # each point's first pair
        least = np.minimum.reduceat(upper, start)  # the least upper bound of each point with a pair
        finalist = lower <= np.repeat(least, np.diff(np.r_[start, len(rows)]))
        rows, face = rows[finalist], face[finalist]
        tri = self.vertices[self.faces[face]]  # (M, 3, 3)
        p = points[rows]
        w = closest_on_triangles(p, tri[:, 0], tri[:, 1], tri[:, 2])  # (M, 3)
        q = np.einsum("mk,mkd->md", w, tri)
        d = np.linalg.norm(p - q, axis=1)
        # The reference's argmin runs over ring slots, and a triangle's first slot is where it counts:
        # among finalists at the same distance, the earliest in ring order wins.
        same = rows[1:] == rows[:-1]
        shared = np.zeros(len(rows), dtype=bool)  # points with several finalists (~6 %)
        shared[:-1] |= same
        shared[1:] |= same
        best = np.flatnonzero(~shared)
        if len(best) < len(rows):
            m = np.flatnonzero(shared)
            slot = np.argmax(cand[rows[m]] == face[m, None], axis=1)
            m = m[np.lexsort((slot, d[m], rows[m]))]
            m = m[np.r_[True, rows[m[1:]] != rows[m[:-1]]]]
            best = np.sort(np.concatenate([best, m]))  # rows ascend with the finalist index
        if len(best) == n:
            return face[best], w[best], q[best]
        # Some points without a triangle around their k vertices: as the reference.
        face_all, bary_all = self._select_reference(points, k)
        found = rows[best]
        face_all[found], bary_all[found] = face[best], w[best]
        return face_all, bary_all, None


QUERY_BLOCK = 4096
QUERY_THREADS = 2
_POOL: list[ThreadPoolExecutor] = []


def _pool() -> ThreadPoolExecutor:
    """The query threads, started once per process."""
    if not _POOL:
        _POOL.append(ThreadPoolExecutor(QUERY_THREADS, thread_name_prefix="closest"))
    return _POOL[0]


class KeptQueries:
    """Closest points on one mesh for a fixed set of ``n`` moving points (a garment's vertices), kept
    between calls: a point that did not move gets its last answer (the query is a function of the
    point alone), so the repair's and the squeeze's rounds only ask for what they moved."""

    def __init__(self, mesh: ClosestPoint, n: int):
        self.mesh = mesh
        self.points = np.full((n, 3), np.nan)  # NaN: never asked
        self.signed = np.zeros(n)
        self.point = np.zeros((n, 3))
        self.normal = np.zeros((n, 3))
        self.rim = np.zeros(n, dtype=bool)

    def at(self, x: np.ndarray, ask: np.ndarray):
        """(signed distance (K,), closest point (K, 3), face normal (K, 3), closest point on the mesh's
        rim (K,) bool) at the points ``ask (K,)`` of ``x (n, 3)``, querying only those that moved since
        they were last asked."""
        stale = ask[np.any(x[ask] != self.points[ask], axis=1)]
        if len(stale):
            q = self.mesh.query(x[stale])
            self.points[stale] = x[stale]
            self.signed[stale], self.point[stale], self.normal[stale] = q.signed, q.point, q.normal
            self.rim[stale] = self.mesh.on_boundary(q)
        return self.signed[ask], self.point[ask], self.normal[ask], self.rim[ask]


def signed_distance(closest: ClosestPoint, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(signed distance (P,), its gradient (P, 3)) to a closed mesh at ``x (P, 3)``: the unit vector
    from the closest point, or the face normal on the surface itself."""
    c = closest.query(x)
    far = c.distance > 1e-9
    sign = np.where(c.signed < 0, -1.0, 1.0)[:, None]
    away = (x - c.point) / np.where(far, c.distance, 1.0)[:, None]
    return c.signed, np.where(far[:, None], sign * away, c.normal)
