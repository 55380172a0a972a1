"""Canonical space: the diffused body-shape displacement B~s(x, beta) (paper 4.1, eq. 9).

A garment vertex x in canonical space (around the mean body) moves with the body:
x_world = x + B~s(x, beta). B~s must equal the body's own displacement on the body surface and
vary smoothly away from it, so a garment carried between bodies neither tears nor folds:

    B~s(x) = (1 - s) * D(closest body point of x) + s * sum_j w_j(x) D_j / sum_j w_j(x)

D_j = body_beta_j - body_mean_j per vertex, D(closest point) its barycentric interpolation,
s = smoothstep(distance / blend) and w_j Gaussian in distance over the nearest vertices, with a
width that grows with the distance. The closest-point term makes it exact on the surface; the
Gaussian term takes over further out, where closest points jump across the medial axis
(between the legs, under the arms). Both are linear in D, so the transfer is a fixed sparse
matrix per point set (``TransferWeights``) applied to any number of shapes.

``transfer_weights_reference`` computes the weights as written; ``transfer_weights`` gives the same
ones (to rounding) with less work, on two threads, and ``to_bodies`` carries a request's garments in
one pass without forming them. The 32 nearest vertices come from cell lists built once
(``service.geometry.near_vertices``, compiled: ~1 us a point against the KD-tree's ~3.5 us). A grid
of B~s per corner body (like ``service.geometry.sdf_grid``) would be cheaper still but misses by up
to 4.9 mm at 6 mm spacing: the truncations to the 32 nearest vertices and the 8 nearest triangles
make B~s jump by ~0.1-1 mm wherever those sets change, which trilinear interpolation cannot follow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix

from service.geometry.closest import ClosestPoint
from service.geometry.closest_kernel import bounding_spheres
from service.geometry.near_vertices import NeighbourCells
from service.pipeline.canonical_kernel import transfer_rows
from service.process.threads import pool

BLEND_DISTANCE = 0.03  # m: beyond it only the smooth term remains
NEIGHBOURS = 32
SIGMA_MIN = 0.01  # m: Gaussian width at the surface; grows as SIGMA_MIN + distance / 2
NEAR_VERTICES = 6  # candidate triangles come from the rings of this many nearest vertices
NEAR_TRIANGLES = 8  # of which the closest this many share the near term
SOFTNESS = 0.5  # soft-min width of the near term, as a fraction of the distance
CHUNK = 2048  # points per block of the fast transfer (measured: 2-4k best on a request's 16k vertices)
MIN_BLOCK = 256  # points: below, one block (the calls cost more than the second thread gains)


@dataclass
class TransferWeights:
    """Sparse rows of the transfer: B~s(points) = sum_k weight[:, k] * D[index[:, k]]."""

    index: np.ndarray  # (N, K) int body vertex ids
    weight: np.ndarray  # (N, K) float, rows sum to 1

    def apply(self, displacement: np.ndarray) -> np.ndarray:
        """Diffused displacement ``(..., N, 3)`` of body displacement ``(..., V, 3)``."""
        displacement = np.asarray(displacement)
        if displacement.shape[-1] != 3:
            raise ValueError(f"displacement must be (..., V, 3), got {displacement.shape}")
        if displacement.ndim != 2:
            return np.einsum("nk,...nkd->...nd", self.weight, displacement[..., self.index, :])
        # One shape: a CSR product sums each row in order, like the einsum, without its (N, K, 3)
        # gather (~4x faster).
        n, k = self.weight.shape
        rows = csr_matrix(
            (self.weight.ravel(), self.index.ravel(), np.arange(0, n * k + 1, k)),
            shape=(n, len(displacement)),
        )
        return rows @ displacement.astype(np.float64, copy=False)


def _check_points(points: np.ndarray) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be (N, 3), got {points.shape}")
    return points


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3 - 2 * t)


@dataclass
class _TransferRows:
    """A block's transfer as its two terms: the far (Gaussian) term on every row, the near term only on
    rows ``near``, the others' (1 - s) being exactly 0."""

    far_index: np.ndarray  # (N, K) int, nearest body vertices
    far_weight: np.ndarray  # (N, K) float, s * Gaussian weights
    near: np.ndarray  # (n,) int rows with a near term
    near_index: np.ndarray  # (n, 3 T) int corners of the chosen triangles
    near_weight: np.ndarray  # (n, 3 T) float, (1 - s) * soft-min * barycentric

    def apply(self, displacement: np.ndarray) -> np.ndarray:
        """Diffused displacement ``(N, 3)`` of body displacement ``(V, 3) float64``."""
        out = TransferWeights(self.far_index, self.far_weight).apply(displacement)
        if len(self.near):
            out[self.near] += TransferWeights(self.near_index, self.near_weight).apply(displacement)
        return out

    def dense(self) -> TransferWeights:
        """As ``(N, 3 T + K)`` rows (near term first), zero near weights on the nearest vertex."""
        n, k = self.far_index.shape
        t3 = self.near_index.shape[1]
        index = np.repeat(self.far_index[:, :1], t3 + k, axis=1)
        weight = np.zeros((n, t3 + k))
        index[:, t3:], weight[:, t3:] = self.far_index, self.far_weight
        if len(self.near):
            index[self.near, :t3], weight[self.near, :t3] = self.near_index, self.near_weight
        return TransferWeights(index, weight)


@dataclass
class CanonicalSpace:
    """The mean body (canonical shape) and its closest-point structure."""

    mean_vertices: np.ndarray  # (V, 3) float64, the body at the canonical shape
    faces: np.ndarray  # (F, 3)
    closest: ClosestPoint
    threads: int = 2  # for transfer_weights

    def __post_init__(self):
        # Filled here, not lazily: the blocks run on threads.
        self._ring = self.closest.ring.astype(np.int32)  # (V, R) faces around each vertex, -1 padded
        self._tree = self.closest.tree
        # The far term's nearest vertices from cell lists built once (~0.7 s, ~16 MB for Anny):
        # the KD-tree's answer at a third of its cost (``service.geometry.near_vertices``).
        self._near = NeighbourCells.build(self.mean_vertices, NEIGHBOURS, self._tree)
        self._spheres = bounding_spheres(self.mean_vertices, self.faces)

    @classmethod
    def build(cls, mean_vertices: np.ndarray, faces: np.ndarray, threads: int = 2) -> CanonicalSpace:
        closest = ClosestPoint.build(mean_vertices, faces)
        return cls(closest.vertices, closest.faces, closest, threads)

    def transfer_weights(self, points: np.ndarray) -> TransferWeights:
        """Weights for canonical ``points (N, 3)``: those of ``transfer_weights_reference`` (to rounding,
        ``tests/pipeline/test_canonical.py``) at ~4x its speed on two cores. Points at least BLEND_DISTANCE
        from the body (where the near term's weights are exactly 0) have them on their nearest vertex.

        Blocks of about CHUNK points, as many for each of the ``threads`` threads, run on a pool kept
        for the process: numpy and the KD-tree release the GIL, and a block's temporaries stay in cache.
        """
        parts = [rows.dense() for rows in self._blocks([_check_points(points)], None)]
        return TransferWeights(
            np.concatenate([t.index for t in parts]), np.concatenate([t.weight for t in parts])
        )

    def _blocks(self, point_sets: list[np.ndarray], displacement: np.ndarray | None) -> list:
        """``_TransferRows`` of the points of all ``point_sets`` in blocks, or with ``displacement
        (V, 3)`` the diffused displacement of each block (applied on the threads)."""
        points = np.concatenate(point_sets) if len(point_sets) > 1 else point_sets[0]
        # A multiple of the threads, so that none waits alone for a last block.
        count = max(1, round(len(points) / CHUNK))
        if len(points) >= self.threads * MIN_BLOCK:
            count = -(-count // self.threads) * self.threads
        blocks = np.array_split(points, count)

        def run(block, workers=1):
            rows = self._transfer_rows(block, workers)
            return rows if displacement is None else rows.apply(displacement)

        if len(blocks) == 1 or self.threads <= 1:
            return [run(b, self.threads) for b in blocks]
        return list(pool("canonical", self.threads).map(run, blocks))

    def _transfer_rows(self, points: np.ndarray, workers: int = 1) -> _TransferRows:
        """``transfer_weights`` of ``points (N, 3) float64`` with less work than the reference: the
        nearest vertices from ``NeighbourCells``, then one compiled loop per point
        (``canonical_kernel.transfer_rows``) that tests each distinct candidate triangle once. Only
        points nearer than BLEND_DISTANCE (s < 1) get a near term: (1 - s) is exactly 0 beyond (on the
        jacket, more than half of the vertices)."""
        vdist, far_index = self._near.query(points)
        n, k = far_index.shape
        t3 = 3 * NEAR_TRIANGLES
        far_weight = np.empty((n, k))
        near_index, near_weight = np.empty((n, t3), dtype=np.int64), np.empty((n, t3))
        has_near = np.empty(n, dtype=np.bool_)
        transfer_rows(points, self.mean_vertices, self.faces, self._spheres, self._ring, vdist, far_index,
                      NEAR_VERTICES, NEAR_TRIANGLES, BLEND_DISTANCE, SIGMA_MIN, SOFTNESS, far_weight,
                      near_index, near_weight, has_near)  # fmt: skip
        near = np.flatnonzero(has_near)
        return _TransferRows(far_index, far_weight, near, near_index[near], near_weight[near])

    def transfer_weights_reference(self, points: np.ndarray) -> TransferWeights:
        """Weights for canonical ``points (N, 3)`` straight from the definition (module docstring)."""
        points = np.asarray(points, dtype=np.float64)
        # Near term: closest points on the triangles around the nearest vertices, soft-minimised
        # with a width proportional to the distance. On the surface the width is 0 (exact);
        # where two parts of the body are almost equally close they share the weight.
        cand, bary, dist = self.closest.candidates(points, k=NEAR_VERTICES)
        order = np.argsort(dist, axis=1)[:, :NEAR_TRIANGLES]
        cand, dist = np.take_along_axis(cand, order, 1), np.take_along_axis(dist, order, 1)
        bary = np.take_along_axis(bary, order[:, :, None], 1)
        d0 = dist[:, :1]
        tau = np.maximum(SOFTNESS * d0, 1e-9)
        soft = np.where(np.isfinite(dist), np.exp(-0.5 * (dist**2 - d0**2) / tau**2), 0.0)
        soft /= soft.sum(axis=1, keepdims=True)
        near_index = self.faces[cand].reshape(len(points), -1)
        near_weight = (soft[:, :, None] * bary).reshape(len(points), -1)
        # Far term: Gaussian over the nearest vertices, wider further out.
        k = min(NEIGHBOURS, len(self.mean_vertices))
        vdist, far_index = self.closest.tree.query(points, k=k, workers=-1)
        vdist, far_index = vdist.reshape(len(points), k), far_index.reshape(len(points), k)
        sigma = SIGMA_MIN + 0.5 * d0
        gauss = np.exp(-0.5 * ((vdist**2 - vdist[:, :1] ** 2) / sigma**2))
        gauss /= gauss.sum(axis=1, keepdims=True)
        s = _smoothstep(d0 / BLEND_DISTANCE)
        index = np.concatenate([near_index, far_index], axis=1)
        weight = np.concatenate([(1 - s) * near_weight, s * gauss], axis=1)
        return TransferWeights(index, weight)

    def displacement(self, points: np.ndarray, body_vertices: np.ndarray) -> np.ndarray:
        """B~s at canonical ``points (N, 3)`` for a body ``(V, 3)`` of the same topology."""
        return self._displacements([_check_points(points)], body_vertices)[0]

    def to_body(self, points: np.ndarray, body_vertices: np.ndarray) -> np.ndarray:
        """Carry canonical ``points (N, 3)`` onto the body: x + B~s(x, beta)."""
        return self.to_bodies([points], body_vertices)[0]

    def to_bodies(self, point_sets: list[np.ndarray], body_vertices: np.ndarray) -> list[np.ndarray]:
        """``to_body`` of several point sets ``(N_i, 3)`` (a request's garments) in one pass of blocks,
        which the threads share evenly; each result is ``to_body``'s bit for bit."""
        point_sets = [_check_points(p) for p in point_sets]
        moved = self._displacements(point_sets, body_vertices)
        return [p + d for p, d in zip(point_sets, moved, strict=True)]

    def _displacements(self, point_sets: list[np.ndarray], body_vertices: np.ndarray) -> list[np.ndarray]:
        body_vertices = np.asarray(body_vertices, dtype=np.float64)
        if body_vertices.shape != self.mean_vertices.shape:
            raise ValueError(f"body_vertices must be {self.mean_vertices.shape}, got {body_vertices.shape}")
        if not point_sets:
            return []
        parts = self._blocks(point_sets, body_vertices - self.mean_vertices)
        return np.split(np.concatenate(parts), np.cumsum([len(p) for p in point_sets])[:-1])

    def to_canonical(
        self,
        points: np.ndarray,
        body_vertices: np.ndarray,
        start: np.ndarray | None = None,
        iterations: int = 30,
        tol: float = 1e-5,
    ) -> tuple[np.ndarray, float]:
        """Invert ``to_body`` for world ``points (N, 3)``: solve x + B~s(x) = y.

        Damped fixed-point iteration x <- x - (x + B~s(x) - y) / 2 from ``start (N, 3)`` (default
        y), on the points whose residual is still above ``tol``. Undamped it oscillates where the
        body compresses space faster than the identity (a heavy body's armpits); halving the step
        keeps it a contraction there. A few points where the nearest-triangle candidates change
        keep a residual of ~0.3 mm (measured on a jacket: 175 of 10,338 vertices).
        Returns (canonical points (N, 3), max residual |x + B~s(x) - y| in metres).
        """
        y = np.asarray(points, dtype=np.float64)
        x = y.copy() if start is None else np.asarray(start, dtype=np.float64).copy()
        active = np.arange(len(y))
        residual = np.zeros(len(y))
        for _ in range(iterations):
            r = x[active] + self.displacement(x[active], body_vertices) - y[active]
            residual[active] = np.linalg.norm(r, axis=1)
            keep = residual[active] >= tol
            x[active[keep]] -= 0.5 * r[keep]
            active = active[keep]
            if not len(active):
                break
        return x, float(residual.max())
