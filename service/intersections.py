"""Exact-predicate triangle-triangle intersection tests (quality measure, DESIGN.md section 7).

Two triangles intersect when an edge of one crosses the other, decided by the signs of
orient3d determinants (float64). Candidates come from a KD-tree on triangle centroids and
bounding-box overlap; ``intersecting_pairs_reference`` is the brute-force twin for tests.
"""

from __future__ import annotations

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
