"""Signed distance to a closed body mesh, for building garments around it.

Distances come from a KD-tree over dense area-uniform surface samples (spacing ~1 mm),
signs from the normal of the nearest sample's triangle (paper 3.1: sign((x - p) . n)).
Accurate to ~0.1 mm at the few-mm offsets garments use; exact closest-point queries would
be ~100x slower for the millions of grid points a catalog build evaluates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from service.geometry.mesh import check_mesh, face_normals


@dataclass
class SurfaceDistance:
    """Signed distance queries against a closed, outward-oriented triangle mesh."""

    samples: np.ndarray  # (S, 3) points on the surface
    normals: np.ndarray  # (S, 3) unit normals of their triangles
    tree: cKDTree
    vertices: np.ndarray  # (V, 3) the mesh vertices
    max_edge: float  # longest edge, bounds how far a vertex can be from the closest point

    @classmethod
    def build(cls, vertices: np.ndarray, faces: np.ndarray, spacing: float = 1e-3, seed: int = 0):
        """Sample the surface with about one point per ``spacing**2`` of area."""
        check_mesh(vertices, faces)
        rng = np.random.default_rng(seed)
        fn = face_normals(vertices, faces, normalize=False)
        area = 0.5 * np.linalg.norm(fn, axis=1)
        n = int(area.sum() / spacing**2)
        tri = rng.choice(len(faces), size=n, p=area / area.sum())
        r1, r2 = rng.random(n), rng.random(n)
        s = np.sqrt(r1)
        w = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)
        v = vertices[faces[tri]]
        # Also keep the vertices: they are the sharpest features of a coarse mesh.
        samples = np.concatenate([np.einsum("nk,nkd->nd", w, v), vertices])
        vn = np.zeros_like(vertices)
        for k in range(3):
            np.add.at(vn, faces[:, k], fn)
        unit_fn = fn / np.maximum(2 * area[:, None], 1e-30)
        normals = np.concatenate([unit_fn[tri], vn / np.linalg.norm(vn, axis=1, keepdims=True)])
        e = vertices[faces] - vertices[np.roll(faces, 1, axis=1)]
        max_edge = float(np.linalg.norm(e, axis=2).max())
        return cls(samples, normals, cKDTree(samples), np.asarray(vertices, float), max_edge)

    def __call__(self, points: np.ndarray, max_distance: float = np.inf) -> np.ndarray:
        """Signed distance ``(N,)`` of points ``(N, 3)``; beyond max_distance returns +-max_distance
        with the sign unknown set to +."""
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points must be (N, 3), got {points.shape}")
        d, i = self.tree.query(points, distance_upper_bound=max_distance, workers=-1)
        far = ~np.isfinite(d)
        i = np.where(far, 0, i)
        sign = np.sign(np.einsum("nd,nd->n", points - self.samples[i], self.normals[i]))
        sign[sign == 0] = 1.0
        return np.where(far, max_distance, sign * d)


def sample_grid(distance: SurfaceDistance, lo: np.ndarray, hi: np.ndarray, voxel: float, band: float):
    """Signed distances on a regular grid covering the box ``lo..hi`` (3,), exact within ``band``.

    Only grid points near the surface are queried against the dense samples (found first
    with the cheap vertex-only tree, whose distance overestimates by at most an edge
    length); the rest get +-band, signed by flood fill: far points connected to the grid's
    border are outside, enclosed ones inside.
    Returns (values (nx, ny, nz) float32, origin (3,), voxel).
    """
    from scipy import ndimage

    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    shape = tuple(np.ceil((hi - lo) / voxel).astype(int) + 1)
    axes = [lo[k] + voxel * np.arange(shape[k]) for k in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    vertex_tree = cKDTree(distance.vertices)
    coarse, _ = vertex_tree.query(pts, distance_upper_bound=band + distance.max_edge, workers=-1)
    near = np.isfinite(coarse)
    values = np.full(len(pts), band, dtype=np.float32)
    values[near] = np.clip(distance(pts[near], max_distance=band), -band, band)
    far = ~near.reshape(shape)
    labels, _ = ndimage.label(far)
    border = np.unique(np.concatenate([
        labels[[0, -1]].ravel(), labels[:, [0, -1]].ravel(), labels[:, :, [0, -1]].ravel()]))
    inside = far & ~np.isin(labels, border)
    values = values.reshape(shape)
    values[inside] = -band
    return values, lo, voxel
