"""Cloth energies of the quasi-static drape, each returning (energy J, gradient (V, 3) N).

Pure numpy functions of vertex positions ``x (V, 3) float64`` and precomputed rest data; the
tests check every gradient against central finite differences.

- membrane: Saint Venant-Kirchhoff, psi = mu |G|^2 + lam/2 tr(G)^2 per rest area, with the Green
  strain G = (F^T F - I) / 2 of each triangle against its shape in the garment template;
- bending: the quadratic bending model of Bergou et al. 2006 (flat rest state, exact for
  isometric deformations), a constant sparse matrix;
- gravity along -Z (Anny's up axis is +Z);
- body collision: a one-sided quadratic penalty on the signed distance to the body below a
  margin, the distance taken against the tangent plane of the nearest dense body sample;
- pin: a quadratic spring holding chosen vertices (a waistband) at target positions;
- friction: static (sticking) friction against the skin, a spring on the tangential part of each
  near-body vertex's motion away from where the garment was put on; free along the normal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from service.geometry.mesh import face_normals

GRAVITY = 9.81  # m / s^2


@dataclass
class RestShape:
    """Per-triangle rest data of a garment template."""

    faces: np.ndarray  # (F, 3) int
    dm_inv: np.ndarray  # (F, 2, 2) inverse of the rest edge matrix in the triangle's own 2-D frame
    area: np.ndarray  # (F,) rest areas, m^2
    vertex_area: np.ndarray  # (V,) a third of the incident rest areas


def rest_shape(vertices: np.ndarray, faces: np.ndarray) -> RestShape:
    """Rest data of the template ``vertices (V, 3)``, ``faces (F, 3)``."""
    v = vertices[faces]
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    n = face_normals(vertices, faces)
    u = e1 / np.linalg.norm(e1, axis=1, keepdims=True)
    w = np.cross(n, u)
    dm = np.stack(
        [np.stack([np.einsum("fd,fd->f", e1, u), np.einsum("fd,fd->f", e2, u)], 1),
         np.stack([np.einsum("fd,fd->f", e1, w), np.einsum("fd,fd->f", e2, w)], 1)], 1)  # fmt: skip
    area = 0.5 * np.abs(np.linalg.det(dm))
    vertex_area = np.zeros(len(vertices))
    for k in range(3):
        np.add.at(vertex_area, faces[:, k], area / 3)
    return RestShape(np.asarray(faces), np.linalg.inv(dm), area, vertex_area)


def deformation_gradient(x: np.ndarray, rest: RestShape) -> np.ndarray:
    """F ``(F, 3, 2)`` of each triangle: deformed edges times the inverse rest edges."""
    v = x[rest.faces]
    ds = np.stack([v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]], axis=2)  # (F, 3, 2)
    return ds @ rest.dm_inv


def green_strain(F: np.ndarray) -> np.ndarray:
    """G = (F^T F - I) / 2, ``(F, 2, 2)`` from ``F (F, 3, 2)``."""
    return 0.5 * (np.swapaxes(F, 1, 2) @ F - np.eye(2))


def _scatter_edges(dE_dds: np.ndarray, faces: np.ndarray, n: int) -> np.ndarray:
    """Gradient ``(V, 3)`` from per-triangle gradients with respect to the edge matrix ``(F, 3, 2)``."""
    per_corner = np.stack([-dE_dds[:, :, 0] - dE_dds[:, :, 1], dE_dds[:, :, 0], dE_dds[:, :, 1]], axis=1)
    idx = faces.reshape(-1)
    # bincount is ~10x faster than np.add.at for this scatter.
    return np.stack([np.bincount(idx, per_corner[:, :, d].reshape(-1), minlength=n) for d in range(3)], 1)


def membrane(x: np.ndarray, rest: RestShape, mu: float, lam: float) -> tuple[float, np.ndarray]:
    """StVK membrane energy; mu, lam are Lame parameters per unit area (N/m)."""
    F = deformation_gradient(x, rest)
    G = green_strain(F)
    tr = G[:, 0, 0] + G[:, 1, 1]
    psi = mu * np.einsum("fij,fij->f", G, G) + 0.5 * lam * tr**2
    S = 2 * mu * G + lam * tr[:, None, None] * np.eye(2)  # second Piola-Kirchhoff stress
    P = F @ S
    dE_dds = rest.area[:, None, None] * P @ np.swapaxes(rest.dm_inv, 1, 2)
    return float(rest.area @ psi), _scatter_edges(dE_dds, rest.faces, len(x))


def _cot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("nd,nd->n", a, b) / np.maximum(np.linalg.norm(np.cross(a, b), axis=1), 1e-30)


def bending_matrix(vertices: np.ndarray, faces: np.ndarray) -> sp.csr_matrix:
    """Bergou's bending matrix Q ``(V, V)``: E = kb/2 * sum_d x[:, d]^T Q x[:, d].

    One 4-vertex stencil per interior edge (x0, x1) with opposite vertices x2, x3:
    K = (c03 + c04, c01 + c02, -c01 - c03, -c02 - c04), Q_e = 3 / (A0 + A1) K K^T.
    """
    half = np.stack([faces, np.roll(faces, -1, axis=1), np.roll(faces, -2, axis=1)], axis=2).reshape(-1, 3)
    key = np.sort(half[:, :2], axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    key, half = key[order], half[order]
    pair = np.flatnonzero(np.all(key[1:] == key[:-1], axis=1))
    a, b = half[pair], half[pair + 1]  # same edge seen from both triangles
    i0, i1, i2, i3 = a[:, 0], a[:, 1], a[:, 2], b[:, 2]
    x = np.asarray(vertices, dtype=np.float64)
    e0, e1, e2 = x[i1] - x[i0], x[i2] - x[i0], x[i3] - x[i0]
    e3, e4 = x[i2] - x[i1], x[i3] - x[i1]
    c01, c02 = _cot(e0, e1), _cot(e0, e2)
    c03, c04 = _cot(-e0, e3), _cot(-e0, e4)
    K = np.stack([c03 + c04, c01 + c02, -c01 - c03, -c02 - c04], axis=1)
    areas = 0.5 * (np.linalg.norm(np.cross(e0, e1), axis=1) + np.linalg.norm(np.cross(e0, e2), axis=1))
    idx = np.stack([i0, i1, i2, i3], axis=1)
    vals = (3.0 / np.maximum(areas, 1e-30))[:, None, None] * K[:, :, None] * K[:, None, :]
    rows = np.repeat(idx[:, :, None], 4, axis=2)
    cols = np.repeat(idx[:, None, :], 4, axis=1)
    n = len(x)
    return sp.csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(n, n))


def bending(x: np.ndarray, Q: sp.csr_matrix, kb: float) -> tuple[float, np.ndarray]:
    """Quadratic bending energy with stiffness kb (N m)."""
    Qx = Q @ x
    return 0.5 * kb * float(np.einsum("vd,vd->", x, Qx)), kb * Qx


def gravity(x: np.ndarray, mass: np.ndarray) -> tuple[float, np.ndarray]:
    """Potential energy of vertex masses ``(V,)`` kg under gravity along -Z."""
    g = np.zeros_like(x)
    g[:, 2] = mass * GRAVITY
    return float(GRAVITY * mass @ x[:, 2]), g


@dataclass
class BodyPlanes:
    """Dense body samples with unit normals, blended into a C1 signed distance.

    d(x) = sum_j w_j (x - s_j) . n_j / sum_j w_j over the samples within ``radius``, with
    w_j = (1 - r_j^2 / radius^2)^2: a sample's weight reaches 0 with zero slope as it leaves the
    ball, so d and its gradient are continuous (the plane of the single nearest sample jumps
    between samples, and L-BFGS line searches stall on it). With no sample in the ball the
    nearest sample's plane is used, which is the limit of the blend as the last one leaves.
    Error against the true distance ~ spacing^2 * curvature, well under 0.1 mm.
    """

    samples: np.ndarray  # (S, 3)
    normals: np.ndarray  # (S, 3)
    tree: cKDTree
    radius: float  # m, ~1.7 sample spacings: about ten samples in the ball
    k: int = 16  # most samples blended; a ball holds ~10 (truncation is rare and only costs C1 there)

    def signed_distance(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(signed distance (V,), its gradient (V, 3)) at points ``x (V, 3)``; negative inside."""
        # One thread: the dataset runs a process per core, and thread start-up costs more than it saves.
        r, j = self.tree.query(x, k=self.k, distance_upper_bound=self.radius)
        inside = np.isfinite(r)
        j = np.where(inside, j, 0)
        diff = x[:, None, :] - self.samples[j]  # (V, k, 3)
        rho = np.where(inside, r**2 / self.radius**2, 1.0)
        w = (1 - rho) ** 2
        dw = (-4 * (1 - rho) / self.radius**2)[:, :, None] * diff  # d w / d x
        n = self.normals[j]
        p = np.einsum("vkd,vkd->vk", diff, n)
        W = w.sum(axis=1)
        blended = W > 0
        Ws = np.where(blended, W, 1.0)
        d = (w * p).sum(axis=1) / Ws
        grad = ((w[:, :, None] * n).sum(axis=1) + ((p - d[:, None])[:, :, None] * dw).sum(axis=1)) / Ws[
            :, None
        ]
        lone = np.flatnonzero(~blended)
        if len(lone):
            _, jn = self.tree.query(x[lone])
            grad[lone] = self.normals[jn]
            d[lone] = np.einsum("vd,vd->v", x[lone] - self.samples[jn], grad[lone])
        return d, grad


class ContactCache:
    """Skips the nearest-sample search for vertices that cannot be within ``margin`` of the body.

    A vertex whose last queried distance was D cannot come within margin of the body before it
    has moved D - margin (the distance is 1-Lipschitz), so only vertices that moved that far,
    or were already close, are searched again. Exact up to ``slack``, which covers the
    tangent-plane approximation of the distance; ~10x fewer searches in a drape.
    """

    def __init__(self, body: BodyPlanes, margin: float, slack: float = 1e-3):
        self.body, self.margin, self.slack = body, margin, slack
        self.anchor: np.ndarray | None = None  # (V, 3) positions at the last search
        self.clearance: np.ndarray | None = None  # (V,) |distance| - margin at the last search

    def gap(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(max(0, margin - d) (V,), normal (V, 3), zero where the gap is 0)."""
        if self.anchor is None or self.anchor.shape != x.shape:
            todo = np.arange(len(x))
            self.anchor, self.clearance = x.copy(), np.zeros(len(x))
        else:
            moved = np.linalg.norm(x - self.anchor, axis=1)
            todo = np.flatnonzero(moved >= self.clearance)
        gap, normal = np.zeros(len(x)), np.zeros_like(x)
        if len(todo):
            d, n = self.body.signed_distance(x[todo])
            self.anchor[todo], self.clearance[todo] = x[todo], d - self.margin - self.slack
            gap[todo] = np.maximum(self.margin - d, 0.0)
            normal[todo] = n
        return gap, normal


def collision(
    x: np.ndarray, body: BodyPlanes | ContactCache, weight: np.ndarray, stiffness: float, margin: float
) -> tuple[float, np.ndarray]:
    """stiffness/2 * sum_v weight_v * max(0, margin - d_v)^2; weight ``(V,)`` (vertex areas).

    ``body`` is the body's planes, or a ContactCache over them built with the same margin.
    """
    if isinstance(body, ContactCache):
        gap, n = body.gap(x)
    else:
        d, n = body.signed_distance(x)
        gap = np.maximum(margin - d, 0.0)
    return 0.5 * stiffness * float(weight @ gap**2), -(stiffness * weight * gap)[:, None] * n


def pin(x: np.ndarray, index: np.ndarray, target: np.ndarray, weight: np.ndarray, stiffness: float):
    """stiffness/2 * sum weight_i |x_i - target_i|^2 over pinned ``index (P,)``."""
    diff = x[index] - target
    g = np.zeros_like(x)
    g[index] = stiffness * weight[:, None] * diff
    return 0.5 * stiffness * float(weight @ np.einsum("pd,pd->p", diff, diff)), g


def friction(
    x: np.ndarray,
    index: np.ndarray,
    anchor: np.ndarray,
    normal: np.ndarray,
    weight: np.ndarray,
    stiffness: float,
):
    """stiffness/2 * sum weight_i |(I - n_i n_i^T)(x_i - anchor_i)|^2 over ``index (P,)``.

    ``anchor (P, 3)`` where each vertex was put on, ``normal (P, 3)`` unit body normals there,
    ``weight (P,)`` per-vertex weights (area times how close to the skin it started).
    """
    diff = x[index] - anchor
    tangential = diff - np.einsum("pd,pd->p", diff, normal)[:, None] * normal
    g = np.zeros_like(x)
    g[index] = stiffness * weight[:, None] * tangential
    return 0.5 * stiffness * float(weight @ np.einsum("pd,pd->p", tangential, tangential)), g
