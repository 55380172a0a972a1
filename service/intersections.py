"""Exact-predicate triangle-triangle intersection tests (quality measure, DESIGN.md section 7).

Two triangles intersect when an edge of one crosses the other, decided by the signs of
orient3d determinants (float64). Candidates come from a KD-tree on triangle centroids and
bounding-box overlap; ``intersecting_pairs_reference`` is the brute-force twin for tests.

``TriangleGrid`` is the repair's path against one fixed mesh tested again and again: its triangles
hashed into cells once, and ``crossing_triangles``, the same determinants as ``triangles_intersect``
computed only where an edge straddles the other plane.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from service.mesh import check_mesh


def orient3d(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Signed volume ``(N,)`` of tetrahedra (a, b, c, d), each ``(N, 3)``: > 0 if d lies above abc."""
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)


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
    """``triangles_intersect(ta, tb)`` bit for bit, given each triangle's ``np.cross(b - a, c - a)``
    (``na``, ``nb``, ``(N, 3)``): the plane sides of the six corners first, then the three edge
    determinants only for the edges that straddle the other plane (a few per cent of the pairs)."""
    hit = np.zeros(len(ta), dtype=bool)
    for t1, t2, n2 in ((ta, tb, nb), (tb, ta, na)):
        side = [np.einsum("ij,ij->i", n2, t1[:, k] - t2[:, 0]) for k in range(3)]  # orient3d(a, b, c, .)
        for k in range(3):
            idx = np.flatnonzero((side[k] * side[(k + 1) % 3] < 0) & ~hit)
            if not len(idx):
                continue
            p, q, a, b, c = t1[idx, k], t1[idx, (k + 1) % 3], t2[idx, 0], t2[idx, 1], t2[idx, 2]
            s1, s2, s3 = orient3d(p, q, a, b), orient3d(p, q, b, c), orient3d(p, q, c, a)
            hit[idx] = ((s1 > 0) & (s2 > 0) & (s3 > 0)) | ((s1 < 0) & (s2 < 0) & (s3 < 0))
    return hit


@dataclass
class Triangles:
    """What the tests need of triangles ``corners (T, 3, 3)``, computed as ``candidate_pairs`` and
    ``triangles_intersect`` compute them (the same bits)."""

    corners: np.ndarray  # (T, 3, 3)
    normal: np.ndarray  # (T, 3) np.cross(b - a, c - a), not unit
    centre: np.ndarray  # (T, 3) centroid
    radius: np.ndarray  # (T,) farthest corner from the centroid
    lo: np.ndarray  # (T, 3) bounding box
    hi: np.ndarray  # (T, 3)

    @classmethod
    def of(cls, corners: np.ndarray) -> Triangles:
        centre = corners.mean(axis=1)
        radius = np.linalg.norm(corners - centre[:, None], axis=2).max(axis=1)
        normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        return cls(corners, normal, centre, radius, corners.min(1), corners.max(1))


_OFFSET = 1 << 20  # cell indices are kept within +-2^20 per axis, so three fit one int64 key


@dataclass
class TriangleGrid:
    """The triangles of a fixed mesh hashed into cubic cells by their bounding boxes, for
    ``crossing`` tests of many other triangles against it (DESIGN: the repair's rounds)."""

    triangles: Triangles
    origin: np.ndarray  # (3,) corner of cell (0, 0, 0)
    cell: float  # m: cell edge
    keys: np.ndarray  # (E,) sorted cell keys of (triangle, cell) entries
    owner: np.ndarray  # (E,) their triangles

    @classmethod
    def build(cls, vertices: np.ndarray, faces: np.ndarray, cell: float | None = None) -> TriangleGrid:
        """``vertices (V, 3)``, ``faces (F, 3)``; ``cell`` defaults to the median bounding-box side
        (fastest on the outfits: larger cells pair more triangles, smaller ones hash more entries)."""
        check_mesh(vertices, faces)
        tri = Triangles.of(np.asarray(vertices, dtype=np.float64)[faces])
        if cell is None:
            side = (tri.hi - tri.lo).max(axis=1)
            cell = float(np.median(side)) if len(side) else 1.0
            cell = cell if cell > 0 else 1.0
        origin = tri.lo.min(axis=0) if len(faces) else np.zeros(3)
        grid = cls(tri, origin, cell, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
        owner, key = grid._entries(tri.lo, tri.hi)[:2]
        order = np.argsort(key, kind="stable")
        grid.keys, grid.owner = key[order], owner[order]
        return grid

    def _index(self, x: np.ndarray) -> np.ndarray:
        """Cell index ``(..., 3)`` of points ``x (..., 3)`` (monotone in x: a box's cells are those
        between its corners' cells)."""
        return np.floor((x - self.origin) / self.cell).astype(np.int64)

    def _entries(self, lo: np.ndarray, hi: np.ndarray):
        """(owner (E,), key (E,), cell index (E, 3)) of every cell each box ``lo, hi (T, 3)`` touches."""
        first, last = self._index(lo), self._index(hi)
        if len(lo) and (np.abs(first).max() >= _OFFSET or np.abs(last).max() >= _OFFSET):
            raise ValueError("meshes too far apart for the grid's cells")
        span = last - first + 1
        count = span.prod(axis=1)
        owner = np.repeat(np.arange(len(lo)), count)
        local = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
        sx, sy = span[owner, 0], span[owner, 1]
        index = first[owner] + np.stack([local % sx, (local // sx) % sy, local // (sx * sy)], axis=1)
        return owner, self._key(index), index

    @staticmethod
    def _key(index: np.ndarray) -> np.ndarray:
        i = index + _OFFSET
        return (i[:, 0] << 42) | (i[:, 1] << 21) | i[:, 2]

    def candidates(self, triangles: Triangles) -> np.ndarray:
        """Index pairs ``(P, 2)`` (into ``triangles``, into the grid's) that ``candidate_pairs`` keeps:
        bounding spheres and boxes overlap. Each pair is found once, in the cell of its boxes'
        overlap's lower corner."""
        b = self.triangles
        if not len(triangles.corners) or not len(b.corners):
            return np.zeros((0, 2), dtype=np.int64)
        try:
            owner, key, index = self._entries(triangles.lo, triangles.hi)
        except ValueError:  # far outside the grid: no cell can be shared
            return np.zeros((0, 2), dtype=np.int64)
        start = np.searchsorted(self.keys, key, side="left")
        count = np.searchsorted(self.keys, key, side="right") - start
        entry = np.repeat(np.arange(len(key)), count)
        slot = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count) + start[entry]
        i, j = owner[entry], self.owner[slot]
        home = self._index(np.maximum(triangles.lo[i], b.lo[j]))
        keep = np.all(home == index[entry], axis=1)
        i, j = i[keep], j[keep]
        overlap = np.all((triangles.lo[i] <= b.hi[j]) & (b.lo[j] <= triangles.hi[i]), axis=1)
        i, j = i[overlap], j[overlap]
        near = np.linalg.norm(triangles.centre[i] - b.centre[j], axis=1) <= triangles.radius[i] + b.radius[j]
        return np.stack([i[near], j[near]], axis=1)

    def crossing(self, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """Pairs ``(K, 2)`` (into ``faces (F, 3)`` over ``vertices (V, 3)``, into the grid's faces)
        that cross: ``intersecting_pairs`` against the grid's mesh, the same set."""
        a = Triangles.of(np.asarray(vertices, dtype=np.float64)[faces])
        pairs = self.candidates(a)
        b = self.triangles
        i, j = pairs[:, 0], pairs[:, 1]
        hit = crossing_triangles(a.corners[i], b.corners[j], a.normal[i], b.normal[j])
        return pairs[hit]


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
