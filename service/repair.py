"""Exact collision repair of the fitted outfit in world space: the guarantee behind the fields.

The field fit (``service.fit``) untangles the layers as the learned fields see them; those are ~1-2 mm
off the meshes, and a fitted mesh can still cross an inner one by that much. This pass makes the
returned meshes satisfy the quality measures of DESIGN.md section 7 exactly, layer by layer from
the body outwards (inner layers are final when an outer one is repaired):

1. Vertices of the layer closer than ``margin`` to an inner layer on its outer side, or on its inner
   side within ``band`` where the inner garment covers (its covariant field h < 0, as in
   ``service.quality.penetration``), move along the inner layer's normal to ``margin`` outside it.
   The body is a closed mesh: every vertex inside it or closer than ``margin`` moves out.
2. The displacement spreads over ``ring`` rings of neighbours (Laplacian diffusion with the moved
   vertices held), so a push lifts a patch instead of a spike.
3. Exact edge-triangle tests find the triangle pairs still crossing (an inner bump poking between
   outer vertices); their outer vertices get twice the margin, and the loop repeats.

Everything is local to the vertices near an inner layer, found with a KD-tree: most vertices are far
from every inner layer and are never touched.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from service.closest import ClosestPoint
from service.fit import dilate, vertex_neighbours
from service.intersections import intersecting_pairs
from service.quality import PENETRATION_BAND

# covers(j, idx (K,)) -> (K,) bool: whether inner layer j covers the layer's vertices idx (its h < 0)
Covers = Callable[[int, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class RepairSettings:
    margin: float = 0.002
    """m: clearance every vertex keeps from the layers inside it."""
    band: float = PENETRATION_BAND
    """m: how deep inside an inner garment a vertex counts as having crossed it."""
    ring: int = 2
    rounds: int = 6
    smoothing: int = 8
    """Jacobi iterations of the displacement diffusion per round."""


@dataclass
class RepairResult:
    vertices: np.ndarray  # (V, 3)
    moved: np.ndarray  # (V,) bool: vertices displaced by the repair
    rounds: int
    crossing_pairs: int  # triangle pairs still crossing an inner layer at the end (0 = success)
    log: list[dict] = field(default_factory=list)


def _pushes(x, inner: ClosestPoint, margin: np.ndarray, band: float, closed: bool, covered):
    """Target positions of the vertices ``x (V, 3)`` that violate ``margin (V,)`` against ``inner``:
    (indices (K,), targets (K, 3))."""
    reach = float(margin.max()) + max(band, 0.0)
    tree = cKDTree(inner.vertices)
    # A vertex farther than reach + the inner mesh's longest edge from every inner vertex is clear.
    edges = inner.vertices[inner.faces] - inner.vertices[inner.faces[:, [1, 2, 0]]]
    longest = float(np.linalg.norm(edges, axis=2).max())
    d_vertex, _ = tree.query(x, distance_upper_bound=reach + longest)
    near = np.flatnonzero(np.isfinite(d_vertex))
    if not len(near):
        return near, np.zeros((0, 3))
    q = inner.query(x[near])
    limit = -np.inf if closed else -band
    bad = (q.signed < margin[near]) & (q.signed > limit)
    if not closed and bad.any():
        bad[bad] = covered(near[bad])
    idx = near[bad]
    normal = q.normal[bad]
    # Out along the face normal from the closest point, to the margin.
    target = q.point[bad] + margin[idx, None] * normal
    return idx, target


def _diffuse(u: np.ndarray, held: np.ndarray, region: np.ndarray, adjacency, iterations: int) -> np.ndarray:
    """Spread displacements ``u (V, 3)`` from ``held`` into ``region`` (both (V,) bool)."""
    free = region & ~held
    if not free.any():
        return u
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    for _ in range(iterations):
        mean = (adjacency @ u) / np.maximum(degree, 1)[:, None]
        u = np.where(free[:, None], mean, u)
    return u


def repair_layer(
    vertices: np.ndarray,
    faces: np.ndarray,
    inner: list[tuple[ClosestPoint, bool]],
    covers: Covers,
    settings: RepairSettings = RepairSettings(),
) -> RepairResult:
    """Repair one layer ``vertices (V, 3)``, ``faces (F, 3)`` against its ``inner`` layers, each a
    (closest-point structure, closed) pair; ``covers(j, idx)`` says where inner layer j covers."""
    x = np.asarray(vertices, dtype=np.float64).copy()
    faces = np.asarray(faces)
    adjacency = vertex_neighbours(faces, len(x))
    margin = np.full(len(x), settings.margin)
    moved = np.zeros(len(x), dtype=bool)
    log = []
    crossing, rounds = 0, 0
    while rounds < settings.rounds:
        rounds += 1
        held = np.zeros(len(x), dtype=bool)
        u = np.zeros_like(x)
        for j, (mesh, closed) in enumerate(inner):
            idx, target = _pushes(x + u, mesh, margin, settings.band, closed, lambda i, j=j: covers(j, i))
            u[idx] = target - x[idx]
            held[idx] = True
        if held.any():
            region = dilate(held, adjacency, settings.ring)
            u = _diffuse(u, held, region, adjacency, settings.smoothing)
            x += u
            moved |= np.linalg.norm(u, axis=1) > 0
        crossing, culprits = 0, []
        for mesh, _ in inner:
            pairs = intersecting_pairs(x, faces, mesh.vertices, mesh.faces)
            crossing += len(pairs)
            culprits.append(faces[pairs[:, 0]].ravel())
        log.append({"pushed": int(held.sum()), "crossing_pairs": crossing})
        if crossing == 0 and not held.any():
            break
        if crossing:
            worse = np.unique(np.concatenate(culprits))
            margin[worse] *= 2
    return RepairResult(x, moved, rounds, crossing, log)
