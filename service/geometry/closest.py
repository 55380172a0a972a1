"""Exact closest points on a triangle mesh.

Used by the canonical space (closest body point of a garment vertex), the drape's body collisions,
and the world-space squeeze and repair (most of a request's closest-point queries).
``closest_on_triangles`` is the vectorised point-triangle test (Ericson, Real-Time Collision
Detection 5.1.5). ``ClosestPoint.query`` finds the closest of all triangles through a hierarchy of
boxes (``bvh_kernel``, compiled); ``ClosestPoint.query_reference`` (``closest_point_reference``)
tests every triangle in numpy, and the two agree bit for bit. ``ClosestPoint.candidates`` (the
triangles around a point's nearest vertices) serves the canonical space's body map.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, fields
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

from service.geometry import bvh_kernel, finish_kernel
from service.geometry.mesh import check_mesh, face_normals
from service.geometry.mesh_topology import LazyPseudoNormals, MeshTopology, PseudoNormals, mesh_topology
from service.process.threads import pool


def _check_points(points: np.ndarray) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be (N, 3), got {points.shape}")
    return points


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Dot products over the last axis (3), summed x, y, then z: the order of the compiled kernel
    (``closest_kernel``), which ``einsum`` does not keep (it adds x and z first)."""
    return u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1] + u[..., 2] * v[..., 2]


def closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Barycentric coordinates ``(..., 3)`` of the point of triangle abc closest to p.

    All inputs ``(..., 3)`` broadcast together. Degenerate triangles fall back to their edges.
    """
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    bp = p - b
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    cp = p - c
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
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


@dataclass
class Closest:
    """Closest mesh points of N query points."""

    face: np.ndarray  # (N,) int, triangle holding the closest point
    bary: np.ndarray  # (N, 3) its barycentric coordinates in that triangle
    point: np.ndarray  # (N, 3) the closest point
    distance: np.ndarray  # (N,) unsigned distance
    signed: np.ndarray  # (N,) signed by the pseudo-normal: negative inside a closed outward mesh
    normal: np.ndarray  # (N, 3) unit normal of that face


def _finish(points, vertices, faces, fn, face, bary, pseudo: PseudoNormals, point=None) -> Closest:
    if point is None:  # else the caller's, computed as here
        point = np.einsum("nk,nkd->nd", bary, vertices[faces[face]])
    diff = points - point
    dist = np.linalg.norm(diff, axis=1)
    side = np.einsum("nd,nd->n", diff, pseudo.at(faces, face, bary, fn))
    sign = np.where(side < 0, -1.0, 1.0)
    return Closest(face, bary, point, dist, sign * dist, fn[face])


def closest_point_reference(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> Closest:
    """Closest points by testing every triangle: O(N F), for tests and small meshes. Of triangles
    at the same distance, the lowest index (``np.argmin``)."""
    points = _check_points(points)
    check_mesh(vertices, faces)
    vertices, faces = np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    face, bary = np.zeros(len(points), dtype=np.int64), np.zeros((len(points), 3))
    tri = vertices[faces]  # (F, 3, 3)
    step = max(1, REFERENCE_PAIRS // max(len(faces), 1))
    for s in range(0, len(points), step):
        p = np.repeat(points[s : s + step], len(faces), axis=0)  # (n F, 3): every pair once
        t = np.tile(tri, (len(p) // max(len(faces), 1), 1, 1))
        w = closest_on_triangles(p, t[:, 0], t[:, 1], t[:, 2])
        d = np.linalg.norm(p - np.einsum("mk,mkd->md", w, t), axis=1).reshape(-1, len(faces))
        best = np.argmin(d, axis=1)
        face[s : s + step] = best
        bary[s : s + step] = w.reshape(-1, len(faces), 3)[np.arange(len(best)), best]
    fn = face_normals(vertices, faces)
    pseudo = PseudoNormals.build(vertices, faces, fn)
    return _finish(points, vertices, faces, fn, face, bary, pseudo)


REFERENCE_PAIRS = 2_000_000  # (point, triangle) pairs per block of the reference: ~0.5 GB of arrays


class ClosestPoint:
    """Closest-point queries against a fixed triangle mesh.

    The search structures are built on the first query: the repair builds one for every layer it
    returns, and nothing asks the outermost. The hierarchy's tree depends on the faces only and is
    kept with their topology (``_hierarchy``): only the boxes are made for each mesh.
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
        # Built for every mesh a request queries (its garments in world space): unbalanced, uncompacted
        # and 32 points a leaf builds in half the time (the jacket: 0.8 against 1.9 ms) and answers
        # the k nearest vertices a little faster (3.0 against 3.3 ms for 3,000 points); any tree's
        # answer is the same.
        return cKDTree(self.vertices, leafsize=32, balanced_tree=False, compact_nodes=False)

    @cached_property
    def boxes(self) -> tuple:
        """The hierarchy of ``bvh_kernel`` over this mesh: (corners (F, 3, 3) in leaf order, the triangles'
        boxes tlo (F, 3), thi (F, 3), the nodes' lo (N, 3), hi (N, 3), left (N,), start (N,), count (N,),
        order (F,))."""
        left, start, count, order = _hierarchy(self.topology, self.faces, self.vertices)
        tri = bvh_kernel.corners(self.vertices, self.faces, order)
        return (tri, *bvh_kernel.triangle_boxes(tri), *bvh_kernel.boxes(tri, left, start, count), left, start,
                count, order)  # fmt: skip

    @cached_property
    def fn(self) -> np.ndarray:
        """(F, 3) unit face normals."""
        return face_normals(self.vertices, self.faces)

    @cached_property
    def pseudo(self) -> PseudoNormals:
        return LazyPseudoNormals.of(self.vertices, self.faces, self.fn, self.topology)

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
        sign says little (a point below a T-shirt's hem reads as inside it). ``on_boundary_reference``
        bit for bit, compiled (``finish_kernel.on_boundary``)."""
        out = np.empty(len(c.face), dtype=np.bool_)
        finish_kernel.on_boundary(self.faces, c.face, np.ascontiguousarray(c.bary), self.boundary_vertices,
                                  self.boundary_edges, len(self.vertices), out)  # fmt: skip
        return out

    def on_boundary_reference(self, c: Closest) -> np.ndarray:
        """``on_boundary`` in numpy."""
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

    def query(self, points: np.ndarray, split: bool = True) -> Closest:
        """Closest points of ``points (N, 3)`` on the mesh: ``query_reference`` bit for bit.

        From ``MIN_SPLIT`` points, blocks of about ``QUERY_BLOCK`` run on ``QUERY_THREADS`` threads (the
        compiled search releases the GIL; each point's answer depends on that point
        alone, so the result is the same bit for bit): the repair's and the squeeze's queries are most
        of a request's time. The blocks are as many as the threads or a multiple, so that none idles
        at the end. ``split=False`` answers on the caller's thread alone (a query asked ahead, in the
        background, which should not take the threads from the queries that are waited for).
        """
        points = _check_points(points)
        if len(points) < MIN_SPLIT or QUERY_THREADS <= 1 or not split:
            return self._query_block(points)
        # Build the lazy structures here: cached_property is not safe to fill from two threads.
        _ = self.topology, self.boxes, self.fn, self.pseudo
        rounds = max(1, round(len(points) / (QUERY_BLOCK * QUERY_THREADS)))
        blocks = np.array_split(points, rounds * QUERY_THREADS)
        parts = list(pool("closest", QUERY_THREADS).map(self._query_block, blocks))
        return Closest(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(Closest)))

    def query_reference(self, points: np.ndarray) -> Closest:
        """``query`` by Ericson's test on every triangle (``closest_point_reference``)."""
        return closest_point_reference(points, self.vertices, self.faces)

    def _query_block(self, points: np.ndarray) -> Closest:
        n = len(points)
        face, bary, point = np.empty(n, dtype=np.int64), np.empty((n, 3)), np.empty((n, 3))
        bvh_kernel.closest(points, *self.boxes, face, bary, point)
        missing = np.flatnonzero(face < 0)
        if len(missing):  # a NaN point, which no box holds: as the reference has it
            ref = closest_point_reference(points[missing], self.vertices, self.faces)
            face[missing], bary[missing], point[missing] = ref.face, ref.bary, ref.point
        return self._finish(points, face, bary, point)

    def _finish(self, points, face, bary, point) -> Closest:
        """The ``Closest`` of ``points (N, 3)`` from their closest faces, barycentric coordinates and points:
        ``_finish``'s (the reference's) bits, compiled (``finish_kernel``), but for the lazy pseudo-normals
        the points reach for the first time, which numpy computes (``LazyPseudoNormals.ready``)."""
        n = len(points)
        kind, index = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
        pseudo = self.pseudo
        finish_kernel.features(self.faces, face, bary, pseudo.edge_keys, len(self.vertices), kind, index)
        pseudo.ready(index[kind == finish_kernel.VERTEX], index[kind == finish_kernel.EDGE])
        dist, signed, normal = np.empty(n), np.empty(n), np.empty((n, 3))
        finish_kernel.finish(points, point, face, kind, index, self.fn, pseudo.vertex, pseudo.edge, dist,
                             signed, normal)  # fmt: skip
        return Closest(face, bary, point, dist, signed, normal)


QUERY_BLOCK = 4096
QUERY_THREADS = 2
MIN_SPLIT = 512
"""Points from which a query is split over the threads. A point costs ~1-2.5 us on one thread, most of
it in the compiled search, which releases the GIL. Measured with the KD-tree search before it, against
the T-shirt's vertices in the jacket: 1,000 points took 2.2 ms in one block and 1.7 in two, 3,000 6.1
and 4.0; 300 gained nothing.
Most of the squeeze's and the repair's queries are of 500-4,000 points, and they run while nothing
else does."""


_TREE_LOCK = threading.Lock()


def _hierarchy(topology: MeshTopology, faces: np.ndarray, vertices: np.ndarray) -> tuple:
    """``bvh_kernel.build`` of ``faces``, built on ``vertices`` the first time these faces are seen and
    kept on their ``MeshTopology`` (one per distinct face array, ``mesh_topology``): a request's
    meshes share their faces with every other request's. The answers of ``closest`` do not depend on
    which vertices it was built on, only how fast they come."""
    with _TREE_LOCK:
        if topology.tree is None:
            topology.tree = bvh_kernel.build(vertices, faces, bvh_kernel.LEAF)
        return topology.tree


def signed_distance(closest: ClosestPoint, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(signed distance (P,), its gradient (P, 3)) to a closed mesh at ``x (P, 3)``: the unit vector
    from the closest point, or the face normal on the surface itself."""
    c = closest.query(x)
    far = c.distance > 1e-9
    sign = np.where(c.signed < 0, -1.0, 1.0)[:, None]
    away = (x - c.point) / np.where(far, c.distance, 1.0)[:, None]
    return c.signed, np.where(far[:, None], sign * away, c.normal)
