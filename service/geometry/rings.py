"""Vertex rings of a triangle mesh: its sparse vertex adjacency, kept per face array, and ring dilation.

The fit, the squeeze and the repair grow a set of vertices by a few rings of neighbours (the conflict
region, the patch a push spreads over) and diffuse displacements over it (``service.geometry.diffusion``).
"""

from __future__ import annotations

import threading

import numpy as np

from service.geometry.mesh_topology import faces_key


def vertex_neighbours(faces: np.ndarray, n_vertices: int):
    """Sparse vertex adjacency ``(V, V)`` of ``faces (F, 3)`` (shared: do not modify it).

    A garment's faces never change, and one request asks for its adjacency in the fit, the squeeze
    and every repair pass: it is built once per distinct face array (by content) and kept."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    key = (n_vertices, faces.shape, faces_key(faces))
    with _ADJACENCY_LOCK:
        found = _ADJACENCY.get(key)
    if found is None:
        found = vertex_neighbours_reference(faces, n_vertices)
        with _ADJACENCY_LOCK:
            while len(_ADJACENCY) >= ADJACENCY_CACHE:
                _ADJACENCY.pop(next(iter(_ADJACENCY)))  # the oldest
            _ADJACENCY[key] = found
    return found


ADJACENCY_CACHE = 32  # face arrays kept: the catalog's garments and a few more
_ADJACENCY: dict = {}
_ADJACENCY_LOCK = threading.Lock()


def vertex_neighbours_reference(faces: np.ndarray, n_vertices: int):
    """``vertex_neighbours`` built afresh."""
    from scipy.sparse import coo_matrix

    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.concatenate([e, e[:, ::-1]])
    return coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_vertices, n_vertices)).tocsr()


def dilate(mask: np.ndarray, adjacency, rings: int) -> np.ndarray:
    """``mask (V,) bool`` grown by ``rings`` rings of neighbours of the adjacency ``(V, V)``
    (``vertex_neighbours``): one sparse product a ring. ``dilate_reference`` walks the edges."""
    out = mask.copy()
    for _ in range(rings):
        out = out | (adjacency @ out.astype(np.float64) > 0)
    return out


def dilate_reference(mask: np.ndarray, faces: np.ndarray, rings: int) -> np.ndarray:
    """``dilate`` by a breadth-first walk over the edges of ``faces (F, 3)``, ring by ring."""
    neighbours: dict[int, set[int]] = {}
    for a, b, c in np.asarray(faces).tolist():
        for u, v in ((a, b), (b, c), (c, a)):
            neighbours.setdefault(u, set()).add(v)
            neighbours.setdefault(v, set()).add(u)
    out = np.asarray(mask, dtype=bool).copy()
    front = set(np.flatnonzero(out).tolist())
    for _ in range(rings):
        front = {w for v in front for w in neighbours.get(v, ())} - set(np.flatnonzero(out).tolist())
        out[list(front)] = True
    return out
