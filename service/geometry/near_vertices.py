"""The k nearest vertices of a fixed point set (the mean body) from precomputed cell lists, compiled.

The body map (``service.pipeline.canonical``) asks for the 32 nearest mean-body vertices of every
garment vertex of a request; scipy's KD-tree answers at ~3.5 us a point. The mean body never
changes, so the work can move to load time: space around it is cut into cubic cells of side h, and
each cell keeps every vertex that can be among the k nearest of *any* point in it. For a cell with
centre c whose k-th nearest vertex is at r_k(c): a point p in the cell has its k nearest within
r_k(p) <= r_k(c) + |p - c| <= r_k(c) + h sqrt(3) / 2 of p, so within r_k(c) + h sqrt(3) of c. A
query then measures the distances to its cell's list (~100 vertices) and keeps the k least, sorted:
the KD-tree's answer, exactly (ties in distance ordered by index). Points in a cell without a list
(farther from the body than ``reach``) fall back to the tree (``NeighbourCells.query``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

CELL = 0.03  # m
REACH = 0.12  # m: cells farther than this from every vertex keep no list
LIST_QUERY = 256  # neighbours asked per cell centre when building; a cell needing more keeps no list
BUILD_CHUNK = 4096  # cell centres per KD query when building (256 neighbours each: ~17 MB)


@njit(cache=True, nogil=True)
def _select_k(queries, points, origin, cell, dims, start, items, reach, k, out_d, out_j, found):
    """The ``k`` nearest of ``points`` for each query whose cell has a list: distances (ascending)
    into ``out_d``, indices into ``out_j``, ``found[q] = True``. A list runs in increasing distance
    ``reach`` from its cell's centre (rounded down), so the scan stops at the first vertex that the
    triangle inequality puts beyond the k-th found so far: those after it are farther still."""
    nx, ny, nz = dims[0], dims[1], dims[2]
    for q in range(len(queries)):
        found[q] = False
        px, py, pz = queries[q, 0], queries[q, 1], queries[q, 2]
        ix = int(np.floor((px - origin[0]) / cell))
        iy = int(np.floor((py - origin[1]) / cell))
        iz = int(np.floor((pz - origin[2]) / cell))
        if ix < 0 or iy < 0 or iz < 0 or ix >= nx or iy >= ny or iz >= nz:
            continue
        cid = (ix * ny + iy) * nz + iz
        a, b = start[cid], start[cid + 1]
        if b - a < k:
            continue
        cx = px - (origin[0] + (ix + 0.5) * cell)
        cy = py - (origin[1] + (iy + 0.5) * cell)
        cz = pz - (origin[2] + (iz + 0.5) * cell)
        off = np.sqrt(cx * cx + cy * cy + cz * cz)  # |p - centre|
        m = 0
        for s in range(a, b):
            if m == k:
                gap = reach[s] - off
                if gap > 0 and gap * gap > out_d[q, k - 1] * (1 + 1e-12):
                    break
            v = items[s]
            dx, dy, dz = px - points[v, 0], py - points[v, 1], pz - points[v, 2]
            x = dx * dx + dy * dy + dz * dz
            if m == k and (x > out_d[q, k - 1] or (x == out_d[q, k - 1] and v > out_j[q, k - 1])):
                continue
            pos = m if m < k else k - 1
            while pos > 0 and (out_d[q, pos - 1] > x or (out_d[q, pos - 1] == x and out_j[q, pos - 1] > v)):
                if pos < k:
                    out_d[q, pos], out_j[q, pos] = out_d[q, pos - 1], out_j[q, pos - 1]
                pos -= 1
            out_d[q, pos], out_j[q, pos] = x, v
            if m < k:
                m += 1
        for s in range(k):
            out_d[q, s] = np.sqrt(out_d[q, s])
        found[q] = True


def _float32_below(x: np.ndarray) -> np.ndarray:
    """``x`` as float32, each value at most ``x`` (a lower bound survives the rounding)."""
    y = x.astype(np.float32)
    return np.where(y > x, np.nextafter(y, np.float32(0)), y)


@dataclass(frozen=True)
class NeighbourCells:
    """Cell lists of ``points (N, 3)`` for exact ``k``-nearest queries (module docstring)."""

    points: np.ndarray
    tree: cKDTree
    k: int
    origin: np.ndarray
    cell: float
    dims: np.ndarray
    start: np.ndarray  # (cells + 1,) int64
    items: np.ndarray  # (sum of list lengths,) int32, each list by distance from its cell's centre
    reach: np.ndarray  # (sum of list lengths,) float32: that distance, rounded down

    @classmethod
    def build(cls, points: np.ndarray, k: int, tree: cKDTree | None = None, cell: float = CELL,
              reach: float = REACH) -> NeighbourCells:  # fmt: skip
        """Lists for every cell within ``reach`` of ``points (N, 3)`` (~0.5 s for the mean body)."""
        points = np.ascontiguousarray(points, dtype=np.float64)
        tree = tree or cKDTree(points)
        k = min(k, len(points))
        origin = points.min(axis=0) - reach
        dims = (np.ceil((points.max(axis=0) + reach - origin) / cell)).astype(np.int64)
        ijk = np.stack(np.meshgrid(*[np.arange(n) for n in dims], indexing="ij"), -1).reshape(-1, 3)
        centres = origin + (ijk + 0.5) * cell
        nearest = tree.query(centres, k=1)[0]
        active = np.flatnonzero(nearest <= reach)
        ask = min(LIST_QUERY, len(points))
        counts = np.zeros(int(dims.prod()), dtype=np.int64)
        lists, reaches = [], []
        for part in np.array_split(active, max(1, len(active) // BUILD_CHUNK)):
            dist, idx = tree.query(centres[part], k=ask, workers=-1)
            dist, idx = dist.reshape(len(part), ask), idx.reshape(len(part), ask)
            radius = dist[:, k - 1] + cell * np.sqrt(3.0)
            # A list is complete only if the ask reached past its radius (or asked for every point).
            complete = (dist[:, -1] > radius) | (ask == len(points))
            within = (dist <= radius[:, None]) & complete[:, None]
            counts[part] = within.sum(axis=1)
            # In increasing distance from the centre (the tree's order), with that distance rounded
            # down for the scan's stopping bound.
            lists.append(idx[within])
            reaches.append(_float32_below(dist[within]))
        start = np.concatenate([[0], np.cumsum(counts)])
        items = np.concatenate(lists).astype(np.int32) if lists else np.zeros(0, dtype=np.int32)
        reach_of = np.concatenate(reaches) if reaches else np.zeros(0, dtype=np.float32)
        return cls(points, tree, k, origin, float(cell), dims, start, items, reach_of)

    def query(self, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(distances (Q, k) ascending, indices (Q, k)): ``cKDTree.query(queries, k)``'s answer."""
        queries = np.ascontiguousarray(queries, dtype=np.float64)
        k = self.k
        out_d, out_j = np.empty((len(queries), k)), np.empty((len(queries), k), dtype=np.int64)
        found = np.empty(len(queries), dtype=np.bool_)
        _select_k(queries, self.points, self.origin, self.cell, self.dims, self.start, self.items,
                  self.reach, k, out_d, out_j, found)  # fmt: skip
        rest = np.flatnonzero(~found)
        if len(rest):
            d, j = self.tree.query(queries[rest], k=k, workers=1)
            out_d[rest], out_j[rest] = d.reshape(len(rest), k), j.reshape(len(rest), k)
        return out_d, out_j
