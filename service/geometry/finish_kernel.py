"""What a closest-point query does after its search, compiled (numba): the feature each closest point lies
on, its signed distance by that feature's pseudo-normal, and whether it is on the mesh's rim.

``service.geometry.closest._finish`` and ``ClosestPoint.on_boundary_reference`` are the numpy twins; these
give the same bits (``tests/geometry/test_closest.py``). The squeeze's and the repair's ~110,000 points a
request (body + 4) spent ~0.6 us each in those numpy passes, a third of the search itself, and held the
GIL for it while the other core's block waited.

A closest point with two barycentric coordinates <= ``ZERO`` is on a vertex (the one left), with one on an
edge (the other two corners), else inside its face.
"""

from __future__ import annotations

import numpy as np
from numba import njit

ZERO = 1e-12
FACE, VERTEX, EDGE = 0, 1, 2


@njit(cache=True, nogil=True, inline="always")
def _feature(faces, t, b0, b1, b2, n_v):
    """(kind, vertex id or edge key) of the closest point with barycentric coordinates b in face t."""
    z0, z1, z2 = b0 <= ZERO, b1 <= ZERO, b2 <= ZERO
    zeros = int(z0) + int(z1) + int(z2)
    if zeros == 2:
        return VERTEX, faces[t, 0] if not z0 else (faces[t, 1] if not z1 else faces[t, 2])
    if zeros == 1:
        if z0:
            a, b = faces[t, 1], faces[t, 2]
        elif z1:
            a, b = faces[t, 0], faces[t, 2]
        else:
            a, b = faces[t, 0], faces[t, 1]
        return EDGE, min(a, b) * n_v + max(a, b)
    return FACE, -1


@njit(cache=True, nogil=True, inline="always")
def _find(keys, key):
    """Row of ``key`` in the sorted ``keys``, or -1 (``np.searchsorted``, clipped, then compared)."""
    if not len(keys):
        return -1
    pos = min(np.searchsorted(keys, key), len(keys) - 1)
    return pos if keys[pos] == key else -1


@njit(cache=True, nogil=True)
def features(faces, face, bary, edge_keys, n_v, kind, index):
    """For closest points ``face (N,)``, ``bary (N, 3)``: ``kind (N,)`` (``VERTEX``, ``EDGE`` or ``FACE``) and
    ``index (N,)``, the vertex id or the edge's row in the sorted ``edge_keys`` (an edge not found there:
    ``FACE``, the face normal, as ``PseudoNormals.at`` has it)."""
    for i in range(len(face)):
        k, key = _feature(faces, face[i], bary[i, 0], bary[i, 1], bary[i, 2], n_v)
        if k == EDGE:
            key = _find(edge_keys, key)
            if key < 0:
                k = FACE
        kind[i], index[i] = k, key


@njit(cache=True, nogil=True)
def finish(points, point, face, kind, index, fn, vertex_normal, edge_normal, dist, signed, normal):
    """Distances ``dist (N,)`` from ``points (N, 3)`` to their closest ``point (N, 3)`` (np.linalg.norm's sum
    x, y, z), signed by the pseudo-normal of their feature (``features``; einsum's dot product, x and z
    added first, then y; negative below it) into ``signed (N,)``, and their face normals ``normal (N, 3)``."""
    for i in range(len(face)):
        dx, dy, dz = points[i, 0] - point[i, 0], points[i, 1] - point[i, 1], points[i, 2] - point[i, 2]
        d = np.sqrt(dx * dx + dy * dy + dz * dz)
        t = face[i]
        if kind[i] == VERTEX:
            n = vertex_normal[index[i]]
        elif kind[i] == EDGE:
            n = edge_normal[index[i]]
        else:
            n = fn[t]
        side = (dx * n[0] + dz * n[2]) + dy * n[1]
        dist[i] = d
        signed[i] = (-1.0 if side < 0 else 1.0) * d
        normal[i, 0], normal[i, 1], normal[i, 2] = fn[t, 0], fn[t, 1], fn[t, 2]


@njit(cache=True, nogil=True)
def on_boundary(faces, face, bary, boundary_vertices, boundary_edges, n_v, out):
    """``out (N,)``: whether each closest point lies on the mesh's rim, an edge with one triangle
    (``boundary_edges``, sorted keys) or one of its ends (``boundary_vertices (V,) bool``)."""
    for i in range(len(face)):
        out[i] = False
        if not len(boundary_edges):
            continue
        k, key = _feature(faces, face[i], bary[i, 0], bary[i, 1], bary[i, 2], n_v)
        if k == VERTEX:
            out[i] = boundary_vertices[key]
        elif k == EDGE:
            out[i] = _find(boundary_edges, key) >= 0
