"""Exact-predicate triangle-triangle intersection tests (quality measure, DESIGN.md section 7).

Two triangles intersect when an edge of one crosses the other, decided by the signs of
orient3d determinants (float64). Candidates come from a KD-tree on triangle centroids and
bounding-box overlap; ``intersecting_pairs_reference`` is the brute-force twin for tests.

``TriangleGrid`` is the repair's path against one fixed mesh tested again and again: its triangles
listed in cells once, so that each pair of overlapping bounding boxes comes up once, and
``crossing_triangles``, the same determinants as ``triangles_intersect`` computed only where an edge
straddles the other plane. It returns the set ``intersecting_pairs`` returns (the same box and sphere
filters, the same bits), tested against the brute-force reference in the tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from service.geometry.mesh import check_mesh


def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``np.cross(u, v)`` of rows ``(N, 3)``, the same bits (its products and differences, in a new
    C-ordered array) without its per-call axis handling, which costs more than the arithmetic here."""
    out = np.empty(np.broadcast_shapes(u.shape, v.shape), dtype=np.result_type(u, v))
    for k in range(3):
        i, j = (k + 1) % 3, (k + 2) % 3
        np.subtract(u[:, i] * v[:, j], u[:, j] * v[:, i], out=out[:, k])
    return out


def orient3d(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Signed volume ``(N,)`` of tetrahedra (a, b, c, d), each ``(N, 3)``: > 0 if d lies above abc."""
    return np.einsum("ij,ij->i", cross(b - a, c - a), d - a)


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
        side = [np.einsum("ij,ij->i", n2, t1[k] - t2[0]) for k in range(3)]  # orient3d(a, b, c, .)
        for k in range(3):
            idx = np.flatnonzero(side[k] * side[(k + 1) % 3] < 0)
            pair.append(idx)
            edge.append([np.take(x, idx, axis=0) for x in (t1[k], t1[(k + 1) % 3], *t2)])
    p, q, a, b, c = (np.concatenate(x) for x in zip(*edge, strict=True))
    s1, s2, s3 = orient3d(p, q, a, b), orient3d(p, q, b, c), orient3d(p, q, c, a)
    hit = np.zeros(len(na), dtype=bool)
    hit[np.concatenate(pair)[((s1 > 0) & (s2 > 0) & (s3 > 0)) | ((s1 < 0) & (s2 < 0) & (s3 < 0))]] = True
    return hit


def bounding_spheres(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroids ``(T, 3)`` and radii ``(T,)`` (farthest corner) of triangles ``corners (T, 3, 3)``,
    computed as ``candidate_pairs`` computes them (the same bits)."""
    centre = corners.mean(axis=1)
    return centre, np.linalg.norm(corners - centre[:, None], axis=2).max(axis=1)


def _corners(vertices: np.ndarray, faces: np.ndarray) -> list[np.ndarray]:
    """The three corners ``(F, 3)`` of triangles ``faces (F, 3)`` over ``vertices (V, 3)``, each
    contiguous: arithmetic on (F, 3) views strided by a triangle costs several times more."""
    return [np.take(vertices, faces[:, k], axis=0) for k in range(3)]


def _normals(corner: list[np.ndarray]) -> np.ndarray:
    """``cross(b - a, c - a)`` ``(F, 3)`` of triangles with corners ``a, b, c (F, 3)``."""
    return cross(corner[1] - corner[0], corner[2] - corner[0])


_ALL_EIGHT = np.frombuffer(np.ones(8, dtype=bool).tobytes(), dtype=np.uint64)[0]  # 8 True bytes
_STEPS = 16  # quantisation steps per cell edge (a power of two: a step's cell is step >> 4)
_MAX_AXIS = 2047  # cells per axis, so that their steps fit int16
_MAX_CELLS = 1 << 21  # cells in a grid's dense rank table (16 MB); the cell edge grows past it


def _overlap(rows_a: np.ndarray, rows_b: np.ndarray) -> np.ndarray:
    """``(N,) bool``: all 8 of each row of ``rows_a >= rows_b`` (``(N, 8)``; 8 bytes of bools a row)."""
    return (rows_a >= rows_b).view(np.uint64)[:, 0] == _ALL_EIGHT


def _box_rows(lo: np.ndarray, hi: np.ndarray, query: bool) -> np.ndarray:
    """Boxes ``lo, hi (N, 3)`` (or transposed views of ``(3, N)``) as ``(N, 8)`` rows that
    ``_overlap(query rows, grid rows)`` compares: hi, -lo, +max for queries and lo, -hi, -max for
    the grid (lo_g <= hi_q and lo_q <= hi_g)."""
    pad = np.inf if lo.dtype.kind == "f" else np.iinfo(lo.dtype).max
    rows = np.empty((len(lo), 8), dtype=lo.dtype)
    rows[:, :3], rows[:, 3:6], rows[:, 6:] = (hi, -lo, pad) if query else (lo, -hi, -pad)
    return rows


# Entries of a cell sorted by their first-cell bits b (bit 0: x, bit 1: y) in Gray order b ^ (b >> 1),
# where every "b covers n" is one run: n = 0 all, 1 {1, 3}, 2 {2, 3}, 3 {3}. Runs [_RUN_LO, _RUN_HI).
_RUN_LO = np.array([0, 1, 2, 2])
_RUN_HI = np.array([4, 3, 4, 3])


@dataclass
class TriangleGrid:
    """The triangles of a fixed mesh listed in the cubic cells their bounding boxes touch, for
    ``crossing`` tests of many other triangles against it (DESIGN: the repair's rounds).

    Two boxes that share cells are paired once, in their home cell: the first cell of their overlap,
    where on each axis the cell is the first of one box or of the other. So a query box asks each of
    its cells only for the entries (triangle, cell) whose cell is their box's first along the axes
    where it is not the query's first: along z, from a second list of the entries first along z;
    along x and y, one run of the cell's entries (sorted as ``_RUN_LO`` says). Every pair comes up
    once, with nothing to deduplicate: pairing all entries that share a cell and then dropping those
    outside their home cell handles up to ten times as many pairs. The cells of the query boxes come
    up column by column (cells are numbered z fastest), and columns with no occupied cell are
    skipped whole.

    Boxes are compared first in int16 steps of 1/16 cell (rounded the same monotone way on both
    sides, so overlapping boxes always pass, and boxes apart by a step are apart): a quarter of the
    bytes of the float test, which then decides only the ties."""

    corner: list[np.ndarray]  # 3 x (F, 3) float64 the triangles' corners a, b, c
    normal: np.ndarray  # (F, 3) cross(b - a, c - a), as crossing_triangles takes them
    box: np.ndarray  # (F, 8) float64 _box_rows
    origin: np.ndarray  # (3,) corner of cell (0, 0, 0)
    cell: float  # m: cell edge
    dims: np.ndarray  # (3,) int64 cells per axis, numbered z fastest
    rank: np.ndarray  # (C + 1,) int64 occupied cells numbered below each cell number
    start: np.ndarray  # (2 (4 U + 1),) int64 entries listed before each (occupied cell, run position):
    # in the list of all entries, then in the list of those first along z (U occupied cells)
    owner: np.ndarray  # (E,) int64 triangles of the entries of both lists
    steps: np.ndarray  # (E, 8) int16 their boxes in steps, as _box_rows

    @classmethod
    def build(cls, vertices: np.ndarray, faces: np.ndarray, cell: float | None = None) -> TriangleGrid:
        """``vertices (V, 3)``, ``faces (F, 3)``; ``cell`` defaults to the median bounding-box side
        (fastest on the outfits: larger cells pair more boxes, smaller ones list more entries), and
        grows where the grid would pass ``_MAX_CELLS`` cells or ``_MAX_AXIS`` along an axis."""
        check_mesh(vertices, faces)
        if cell is not None and not 0 < cell < np.inf:
            raise ValueError(f"cell must be positive and finite, got {cell}")
        corner = _corners(np.asarray(vertices, dtype=np.float64), np.asarray(faces))
        lo = np.minimum(np.minimum(corner[0], corner[1]), corner[2])
        hi = np.maximum(np.maximum(corner[0], corner[1]), corner[2])
        extent = (hi - lo).T
        side = np.maximum(np.maximum(extent[0], extent[1]), extent[2])
        if cell is None:
            cell = float(np.median(side)) if len(side) else 1.0
            cell = cell if cell > 0 else 1.0
        origin = lo.min(axis=0) if len(lo) else np.zeros(3)
        span = (hi.max(axis=0) - origin) if len(lo) else np.zeros(3)
        cell = max(cell, float(span.max()) / (_MAX_AXIS - 1))
        # Cells counted from the steps of the highest corner, rounded as _steps rounds it (span / cell
        # can round below a whole number that the steps reach).
        while (dims := (np.floor(span * (_STEPS / cell)).astype(np.int64) >> 4) + 1).prod() > _MAX_CELLS:
            cell *= 1.01 * (dims.prod() / _MAX_CELLS) ** (1 / 3)
        empty = np.zeros(0, dtype=np.int64)
        grid = cls(corner, _normals(corner), _box_rows(lo, hi, query=False), origin,
                   float(cell), dims, empty, empty, empty, empty)  # fmt: skip
        grid._list(lo, hi)
        return grid

    def _steps(self, x: np.ndarray) -> np.ndarray:
        """Quantised points ``x (N, 3)``, as ``(3, N)`` int16 steps of ``cell / _STEPS`` from the
        origin, -1 or ``dims * _STEPS`` outside the grid. Monotone in x, so boxes that overlap keep
        overlapping (and a box's cells are those between its corners' cells, ``steps >> 4``)."""
        u = (x.T - self.origin[:, None]) * (_STEPS / self.cell)  # (3, N): long inner loops
        np.maximum(u, -1.0, out=u)
        np.minimum(u, self.dims[:, None] * float(_STEPS), out=u)
        return np.floor(u, out=u).astype(np.int16)

    def _cells(self, first: np.ndarray, last: np.ndarray, columns_only_occupied: bool = False):
        """Every cell of boxes with cells ``first..last (3, N)`` int64: (box (M,), bits (M,) int64 of
        the axes where it is not the box's first cell (1 x, 2 y, 4 z), cell number (M,)). Expanded
        axis by axis with repeats (integer division costs more than all of them); optionally
        skipping the (x, y) columns with no occupied cell in the box's z range."""
        fx, fy, fz = first
        _, ny, nz = (int(d) for d in self.dims)
        box, dx = _expand(last[0] - fx + 1)
        line = (fx[box] + dx) * ny
        at, dy = _expand((last[1] - fy + 1)[box])
        box = box[at]
        bits = (dx[at] != 0) | ((dy != 0) << 1)
        number = (line[at] + fy[box] + dy) * nz + fz[box]  # the column's first cell
        depth = last[2][box] - fz[box] + 1
        if columns_only_occupied:
            some = np.flatnonzero(self.rank[number + depth] > self.rank[number])
            box, bits, number, depth = box[some], bits[some], number[some], depth[some]
        at, dz = _expand(depth)
        return box[at], bits[at] | ((dz != 0) << 2), number[at] + dz

    def _list(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Fill ``rank``, ``start``, ``owner`` and ``steps`` from the grid's boxes ``lo, hi (F, 3)``."""
        step_lo, step_hi = self._steps(lo), self._steps(hi)
        owner, bits, number = self._cells((step_lo >> 4).astype(np.int64), (step_hi >> 4).astype(np.int64))
        first = 3 - (bits & 3)  # along x and y, whether the cell is the box's first
        key = number * 4 + (first ^ (first >> 1))  # cell, then run position
        # Two stable radix passes of 16 bits: numpy sorts 16-bit keys by radix, and a comparison sort
        # of the entries would cost more than the rest of the build.
        order = np.argsort((key & 0xFFFF).astype(np.uint16), kind="stable")
        order = order[np.argsort((key[order] >> 16).astype(np.uint16), kind="stable")]
        key, owner, z_first = key[order], owner[order], bits[order] < 4
        new = np.ones(len(key), dtype=bool)
        new[1:] = (key[1:] >> 2) != (key[:-1] >> 2)
        slot = (np.cumsum(new) - 1) * 4 + (key & 3)  # (occupied cell, run position)
        size = 4 * int(new.sum())
        mark = np.zeros(int(self.dims.prod()) + 1, dtype=np.int64)
        mark[(key[new] >> 2) + 1] = 1
        self.rank = np.cumsum(mark)
        below = [
            np.concatenate([[0], np.cumsum(np.bincount(s, minlength=size))]) for s in (slot, slot[z_first])
        ]
        self.start = np.concatenate([below[0], below[1] + len(key)])
        self.owner = np.concatenate([owner, owner[z_first]])
        self.steps = np.take(_box_rows(step_lo.T, step_hi.T, query=False), self.owner, axis=0)

    def candidates(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Index arrays ``i, j (P,)`` (into boxes ``lo, hi (N, 3)``, into the grid's triangles) of all
        pairs of overlapping boxes (``lo <= hi`` both ways on every axis), each once."""
        step_lo, step_hi = self._steps(lo), self._steps(hi)
        first, last = (step_lo >> 4).astype(np.int64), (step_hi >> 4).astype(np.int64)
        inside = np.flatnonzero(
            (last[0] >= 0) & (last[1] >= 0) & (last[2] >= 0)
            & (first[0] < self.dims[0]) & (first[1] < self.dims[1]) & (first[2] < self.dims[2])
        )  # fmt: skip
        first = np.maximum(np.take(first, inside, axis=1), 0)
        last = np.minimum(np.take(last, inside, axis=1), self.dims[:, None] - 1)
        query, bits, number = self._cells(first, last, columns_only_occupied=True)
        rank = self.rank[number]
        some = np.flatnonzero(self.rank[number + 1] > rank)  # occupied cells
        need = bits[some] & 3  # the entries must be first along the axes where the query is not
        at = rank[some] * 4 + np.where(bits[some] < 4, 0, len(self.start) // 2)
        begin = self.start[at + _RUN_LO[need]]
        count = self.start[at + _RUN_HI[need]] - begin
        keep = np.flatnonzero(count)
        begin, count, query = begin[keep], count[keep], inside[query[some[keep]]]
        end = np.cumsum(count)
        slot = np.arange(int(end[-1]) if len(end) else 0) + np.repeat(begin - (end - count), count)
        rows = np.repeat(np.take(_box_rows(step_lo.T, step_hi.T, query=True), query, axis=0), count, axis=0)
        steps = np.take(self.steps, slot, axis=0)
        near = np.flatnonzero(_overlap(rows, steps))
        i, j = np.repeat(query, count)[near], self.owner[slot[near]]
        # Steps strictly apart on every side mean floats strictly apart too (monotone rounding).
        tie = np.flatnonzero(~_overlap(np.take(rows, near, axis=0), np.take(steps, near, axis=0) + 1))
        keep = np.ones(len(i), dtype=bool)
        box = _box_rows(np.take(lo, i[tie], axis=0), np.take(hi, i[tie], axis=0), query=True)
        keep[tie] = _overlap(box, np.take(self.box, j[tie], axis=0))
        return i[keep], j[keep]

    def crossing(self, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """Pairs ``(K, 2)`` (into ``faces (F, 3)`` over ``vertices (V, 3)``, into the grid's faces)
        that cross: ``intersecting_pairs`` against the grid's mesh, the same set.

        The pairs ``candidate_pairs`` keeps (bounding boxes overlap, then spheres) that
        ``crossing_triangles`` finds crossing: the spheres are tested last, on the few crossing
        pairs, since the order of the filters changes nothing."""
        corner = _corners(np.asarray(vertices, dtype=np.float64), np.asarray(faces))
        if not len(corner[0]) or not len(self.normal):
            return np.zeros((0, 2), dtype=np.int64)
        lo = np.minimum(np.minimum(corner[0], corner[1]), corner[2])
        hi = np.maximum(np.maximum(corner[0], corner[1]), corner[2])
        i, j = self.candidates(lo, hi)
        used = np.zeros(len(lo), dtype=bool)
        used[i] = True
        mine = np.cumsum(used)[i] - 1  # pairs' query triangles among the used ones
        corner = [c[used] for c in corner]
        normal = _normals(corner)
        ca = [np.take(c, mine, axis=0) for c in corner]
        cb = [np.take(c, j, axis=0) for c in self.corner]
        na, nb = np.take(normal, mine, axis=0), np.take(self.normal, j, axis=0)
        hit = np.flatnonzero(_crossing(ca, cb, na, nb))
        (sa, ra), (sb, rb) = (bounding_spheres(np.stack([x[hit] for x in c], axis=1)) for c in (ca, cb))
        hit = hit[np.linalg.norm(sa - sb, axis=1) <= ra + rb]
        return np.stack([i[hit], j[hit]], axis=1)


def _expand(count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For ``count (N,)`` items each: their owner (M,) and index among the owner's items (M,)."""
    owner = np.repeat(np.arange(len(count)), count)
    return owner, np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)


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
