"""Exact-predicate triangle-triangle intersection tests (quality measure, docs/design.md section 7).

Two triangles intersect when an edge of one crosses the other, decided by the signs of
orient3d determinants (float64). Candidates come from a KD-tree on triangle centroids and
bounding-box overlap; ``intersecting_pairs_reference`` is the brute-force twin for tests.

``TriangleGrid`` is the repair's path against one fixed mesh tested again and again: its triangles
listed in cells once, and the tests compiled (``service.geometry.grid_kernel``), the same
determinants as ``triangles_intersect`` computed only where an edge straddles the other plane
(``crossing_triangles`` is that in numpy). It returns the set ``intersecting_pairs`` returns (the same
box and sphere filters, the same bits), tested against the brute-force reference in the tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from service.geometry.grid_kernel import corner_boxes, fill, pairs
from service.geometry.mesh import check_mesh
from service.process.threads import pool


def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``np.cross(u, v)`` of rows ``(N, 3)``, the same bits (its products and differences, in a new
    C-ordered array) without its per-call axis handling, which costs more than the arithmetic here."""
    out = np.empty(np.broadcast_shapes(u.shape, v.shape), dtype=np.result_type(u, v))
    for k in range(3):
        i, j = (k + 1) % 3, (k + 2) % 3
        np.subtract(u[:, i] * v[:, j], u[:, j] * v[:, i], out=out[:, k])
    return out


def dot3(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row dot products ``(N,)`` of ``(N, 3)`` arrays, summed x, y, then z: the compiled kernels'
    order (``grid_kernel``; ``einsum`` adds x and z first), so that both decide the same signs."""
    return u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1] + u[:, 2] * v[:, 2]


def orient3d(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Signed volume ``(N,)`` of tetrahedra (a, b, c, d), each ``(N, 3)``: > 0 if d lies above abc."""
    return dot3(cross(b - a, c - a), d - a)


def segments_cross_triangles(p, q, a, b, c) -> np.ndarray:
    """Whether segment pq properly crosses triangle abc, all ``(N, 3)``; returns ``(N,) bool``.

    Touching or coplanar configurations count as not crossing.
    """
    d1, d2 = orient3d(a, b, c, p), orient3d(a, b, c, q)
    s1, s2, s3 = orient3d(p, q, a, b), orient3d(p, q, b, c), orient3d(p, q, c, a)
    straddle = d1 * d2 < 0
    same = ((s1 > 0) & (s2 > 0) & (s3 > 0)) | ((s1 < 0) & (s2 < 0) & (s3 < 0))
    return straddle & same


def triangles_intersect(ta: np.ndarray, tb: np.ndarray) -> np.ndarray:
    """Pairwise test of triangles ``ta (N, 3, 3)`` against ``tb (N, 3, 3)``: ``(N,) bool``."""
    hit = np.zeros(len(ta), dtype=bool)
    for t1, t2 in ((ta, tb), (tb, ta)):
        for k in range(3):
            p, q = t1[:, k], t1[:, (k + 1) % 3]
            hit |= segments_cross_triangles(p, q, t2[:, 0], t2[:, 1], t2[:, 2])
    return hit


def crossing_triangles(ta: np.ndarray, tb: np.ndarray, na: np.ndarray, nb: np.ndarray) -> np.ndarray:
    """``triangles_intersect(ta, tb)`` bit for bit, given each triangle's ``cross(b - a, c - a)``
    (``na``, ``nb``, ``(N, 3)``): the plane sides of the six corners first, then the three edge
    determinants only for the edges that straddle the other plane (a few per cent of the pairs),
    all of them in one batch."""
    corners = ([np.take(t, k, axis=1) for k in range(3)] for t in (ta, tb))
    return _crossing(*corners, na, nb)


def _crossing(ca: list[np.ndarray], cb: list[np.ndarray], na: np.ndarray, nb: np.ndarray) -> np.ndarray:
    """``crossing_triangles`` of triangles given by their corners, each ``(N, 3)`` contiguous."""
    pair, edge = [], []  # per straddling edge pq of t1: its pair, and p, q and the corners of t2
    for t1, t2, n2 in ((ca, cb, nb), (cb, ca, na)):
        side = [dot3(n2, t1[k] - t2[0]) for k in range(3)]  # orient3d(a, b, c, .)
        for k in range(3):
            idx = np.flatnonzero(side[k] * side[(k + 1) % 3] < 0)
            pair.append(idx)
            edge.append([np.take(x, idx, axis=0) for x in (t1[k], t1[(k + 1) % 3], *t2)])
    p, q, a, b, c = (np.concatenate(x) for x in zip(*edge, strict=True))
    s1, s2, s3 = orient3d(p, q, a, b), orient3d(p, q, b, c), orient3d(p, q, c, a)
    hit = np.zeros(len(na), dtype=bool)
    hit[np.concatenate(pair)[((s1 > 0) & (s2 > 0) & (s3 > 0)) | ((s1 < 0) & (s2 < 0) & (s3 < 0))]] = True
    return hit


def _normals(corner: list[np.ndarray]) -> np.ndarray:
    """``cross(b - a, c - a)`` ``(F, 3)`` of triangles with corners ``a, b, c (F, 3)``."""
    return cross(corner[1] - corner[0], corner[2] - corner[0])


_MAX_CELLS = 1 << 21  # cells in a grid (16 MB of cell starts); the cell edge grows past it


CROSSING_SPLIT = 1000
"""Triangles from which ``TriangleGrid.crossing`` splits its tests over ``CROSSING_THREADS`` threads:
a repair's first round tests thousands (the tested triangles of four tops: 81,000 in 16 calls per
request, 58 ms on one thread)."""
CROSSING_THREADS = 2


@dataclass
class TriangleGrid:
    """The triangles of a fixed mesh listed in the cubic cells their bounding boxes touch, for
    ``crossing`` tests of many other triangles against it (the repair's rounds). The lists and the
    tests are compiled (``service.geometry.grid_kernel``); ``crossing`` returns the set
    ``intersecting_pairs`` returns (the same box and sphere filters, the same bits)."""

    corners: np.ndarray  # (F, 3, 3) float64
    normal: np.ndarray  # (F, 3) cross(b - a, c - a), as crossing_triangles takes them
    lo: np.ndarray  # (F, 3) bounding boxes
    hi: np.ndarray
    origin: np.ndarray  # (3,) corner of cell (0, 0, 0)
    cell: float  # m: cell edge
    dims: np.ndarray  # (3,) int64 cells per axis, numbered z fastest
    start: np.ndarray  # (C + 1,) int64: cell c's triangles are items[start[c]:start[c + 1]]
    items: np.ndarray  # (E,) int64

    @classmethod
    def build(cls, vertices: np.ndarray, faces: np.ndarray, cell: float | None = None) -> TriangleGrid:
        """``vertices (V, 3)``, ``faces (F, 3)``; ``cell`` defaults to the median bounding-box side
        (larger cells pair more boxes, smaller ones list more entries), and grows where the grid
        would pass ``_MAX_CELLS`` cells."""
        check_mesh(vertices, faces)
        if cell is not None and not 0 < cell < np.inf:
            raise ValueError(f"cell must be positive and finite, got {cell}")
        corners, lo, hi = corner_boxes_of(vertices, faces)
        if cell is None:
            side = (hi - lo).max(axis=1) if len(lo) else np.ones(1)
            cell = float(np.median(side)) if len(side) else 1.0
            cell = cell if cell > 0 else 1.0
        origin = lo.min(axis=0) if len(lo) else np.zeros(3)
        span = (hi.max(axis=0) - origin) if len(lo) else np.zeros(3)
        while (count := float(np.prod(np.floor(span / cell) + 1))) > _MAX_CELLS:  # in floats: no overflow
            cell *= 1.01 * (count / _MAX_CELLS) ** (1 / 3)
        dims = np.floor(span / cell).astype(np.int64) + 1
        start, items = fill(lo, hi, origin, float(cell), dims)
        normal = _normals([corners[:, k] for k in range(3)])
        return cls(corners, normal, lo, hi, origin, float(cell), dims, start, items)

    def _pairs(self, corners: np.ndarray, lo: np.ndarray, hi: np.ndarray, exact: bool) -> np.ndarray:
        return pairs(corners, lo, hi, self.corners, self.normal, self.lo, self.hi, self.origin, self.cell,
                     self.dims, self.start, self.items, exact)  # fmt: skip

    def candidates(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Index arrays ``i, j (P,)`` (into boxes ``lo, hi (N, 3)``, into the grid's triangles) of all
        pairs of overlapping boxes (``lo <= hi`` both ways on every axis), each once."""
        lo, hi = (np.ascontiguousarray(x, dtype=np.float64) for x in (lo, hi))
        found = self._pairs(np.zeros((len(lo), 3, 3)), lo, hi, exact=False)
        return found[:, 0], found[:, 1]

    def crossing(self, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """Pairs ``(K, 2)`` (into ``faces (F, 3)`` over ``vertices (V, 3)``, into the grid's faces)
        that cross: ``intersecting_pairs`` against the grid's mesh, the same set."""
        corners, lo, hi = corner_boxes_of(vertices, faces)
        if not len(corners) or not len(self.normal):
            return np.zeros((0, 2), dtype=np.int64)
        if len(corners) < CROSSING_SPLIT or CROSSING_THREADS <= 1:
            return self._pairs(corners, lo, hi, exact=True)
        # Halves on two threads (the kernel releases the GIL): its pairs come in query order, so the
        # halves' pairs, the second's indices shifted, are the whole call's, in the same order.
        cut = np.array_split(np.arange(len(corners)), CROSSING_THREADS)
        parts = list(pool("crossing", CROSSING_THREADS).map(
            lambda i: self._pairs(corners[i], lo[i], hi[i], exact=True), cut))  # fmt: skip
        for i, part in zip(cut, parts, strict=True):
            part[:, 0] += i[0] if len(i) else 0
        return np.concatenate(parts)


def corner_boxes_of(vertices, faces) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(corners (F, 3, 3), lo, hi (F, 3)) of ``faces (F, 3)`` over ``vertices (V, 3)``: ``vertices[faces]``
    and its min and max over the corners (compiled, ``grid_kernel.corner_boxes``)."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    corners, lo, hi = np.empty((len(faces), 3, 3)), np.empty((len(faces), 3)), np.empty((len(faces), 3))
    corner_boxes(vertices, faces, corners, lo, hi)
    return corners, lo, hi


def candidate_pairs(va, fa, vb, fb) -> np.ndarray:
    """Triangle index pairs ``(P, 2)`` (into fa, fb) whose bounding boxes overlap."""
    if len(fa) == 0 or len(fb) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    ta, tb = va[fa], vb[fb]
    ca, cb = ta.mean(axis=1), tb.mean(axis=1)
    ra = np.linalg.norm(ta - ca[:, None], axis=2).max(axis=1)
    rb = np.linalg.norm(tb - cb[:, None], axis=2).max(axis=1)
    # Centroid pairs closer than the two largest circumradii, as one array (query_ball_point's
    # per-point Python lists cost more than the tests); the bounding boxes then prune them.
    radius = float(ra.max() + rb.max())
    pairs = cKDTree(ca).sparse_distance_matrix(cKDTree(cb), radius, output_type="ndarray")
    i, j = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
    keep = np.linalg.norm(ca[i] - cb[j], axis=1) <= ra[i] + rb[j]
    i, j = i[keep], j[keep]
    lo_a, hi_a, lo_b, hi_b = ta.min(1), ta.max(1), tb.min(1), tb.max(1)
    overlap = np.all((lo_a[i] <= hi_b[j]) & (lo_b[j] <= hi_a[i]), axis=1)
    return np.stack([i[overlap], j[overlap]], axis=1)


def intersecting_pairs(va, fa, vb=None, fb=None) -> np.ndarray:
    """Intersecting triangle pairs ``(K, 2)`` between mesh a and mesh b, or within mesh a
    (self-intersections; pairs sharing a vertex are skipped, each pair reported once)."""
    check_mesh(va, fa)
    self_test = vb is None
    if self_test:
        vb, fb = va, fa
    check_mesh(vb, fb)
    pairs = candidate_pairs(va, fa, vb, fb)
    if self_test:
        pairs = pairs[pairs[:, 0] < pairs[:, 1]]
        shared = (fa[pairs[:, 0], :, None] == fa[pairs[:, 1], None, :]).any(axis=(1, 2))
        pairs = pairs[~shared]
    hit = np.zeros(len(pairs), dtype=bool)
    for s in range(0, len(pairs), 200_000):  # bounded memory
        chunk = pairs[s : s + 200_000]
        hit[s : s + 200_000] = triangles_intersect(va[fa[chunk[:, 0]]], vb[fb[chunk[:, 1]]])
    return pairs[hit]


def intersecting_pairs_reference(va, fa, vb, fb) -> np.ndarray:
    """All-pairs version of ``intersecting_pairs`` between two meshes (small meshes only)."""
    i, j = np.meshgrid(np.arange(len(fa)), np.arange(len(fb)), indexing="ij")
    i, j = i.ravel(), j.ravel()
    hit = triangles_intersect(va[fa[i]], vb[fb[j]])
    return np.stack([i[hit], j[hit]], axis=1)


def segment_crossings(grid: TriangleGrid, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(N,)`` int: how many of the grid mesh's triangles each segment ``p[n] q[n]`` (``(N, 3)``)
    properly crosses (``segments_cross_triangles``; touching does not count). Odd: p and q lie on
    two sides of a closed sheet of the mesh."""
    lo, hi = np.minimum(p, q), np.maximum(p, q)
    i, j = grid.candidates(lo, hi)
    corners = grid.corners[j]
    hit = segments_cross_triangles(p[i], q[i], corners[:, 0], corners[:, 1], corners[:, 2])
    return np.bincount(i[hit], minlength=len(p))


def segment_crossings_reference(vertices, faces, p, q) -> np.ndarray:
    """All-pairs version of ``segment_crossings`` (small meshes only)."""
    tri = vertices[faces]
    n, f = len(p), len(faces)
    i, j = np.repeat(np.arange(n), f), np.tile(np.arange(f), n)
    hit = segments_cross_triangles(p[i], q[i], tri[j, 0], tri[j, 1], tri[j, 2])
    return np.bincount(i[hit], minlength=n)
