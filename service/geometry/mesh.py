"""Pure mesh helpers shared by training and serving (numpy; the face normals compiled with numba).

Meshes are ``vertices (V, 3) float`` and ``faces (F, 3) int`` with counter-clockwise
triangles seen from the side their normals point to.
"""

from __future__ import annotations

import numpy as np
from numba import njit


def check_mesh(vertices: np.ndarray, faces: np.ndarray) -> None:
    """Raise ValueError unless vertices is (V, 3) finite and faces (F, 3) indexes into it."""
    vertices = np.asarray(vertices)
    faces = np.asarray(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"vertices must be (V, 3), got {vertices.shape}")
    if not np.all(np.isfinite(vertices)):
        raise ValueError("vertices must be finite")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"faces must be (F, 3), got {faces.shape}")
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise ValueError("faces index outside vertices")


def face_normals(vertices: np.ndarray, faces: np.ndarray, normalize: bool = True) -> np.ndarray:
    """Normals ``(F, 3)``; unnormalised ones have length twice the triangle area.

    ``face_normals_reference`` bit for bit: np.cross's products and differences and np.linalg.norm's
    sum of squares, in their order, in one compiled pass (``_face_normals``): every mesh a request
    queries needs them, and the numpy form's (F, 3, 3) gather took 1.5 ms for the body."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    n = np.empty((len(faces), 3))
    _face_normals(vertices, faces, normalize, n)
    return n


@njit(cache=True, nogil=True)
def _face_normals(vertices, faces, normalize, n):
    for t in range(len(faces)):
        i, j, k = faces[t, 0], faces[t, 1], faces[t, 2]
        a0, a1, a2 = (
            vertices[j, 0] - vertices[i, 0],
            vertices[j, 1] - vertices[i, 1],
            vertices[j, 2] - vertices[i, 2],
        )
        b0, b1, b2 = (
            vertices[k, 0] - vertices[i, 0],
            vertices[k, 1] - vertices[i, 1],
            vertices[k, 2] - vertices[i, 2],
        )
        n0, n1, n2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
        if normalize:
            length = max(np.sqrt(n0 * n0 + n1 * n1 + n2 * n2), 1e-30)
            n0, n1, n2 = n0 / length, n1 / length, n2 / length
        n[t, 0], n[t, 1], n[t, 2] = n0, n1, n2


def face_normals_reference(vertices: np.ndarray, faces: np.ndarray, normalize: bool = True) -> np.ndarray:
    """``face_normals`` with np.cross and np.linalg.norm."""
    v = vertices[faces]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    if normalize:
        n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    return n


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals ``(V, 3)``: ``vertex_normals_reference`` bit for bit, in one
    compiled pass (``_vertex_normals``; every fit takes its garment's)."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    fn = face_normals(vertices, faces, normalize=False)
    vn = np.zeros((len(vertices), 3))
    _vertex_normals(faces, fn, vn)
    return vn


@njit(cache=True, nogil=True)
def _vertex_normals(faces, fn, vn):
    """The face normals summed into their corners, corner 0 of every face first, then 1, then 2 (the
    reference's bincount order), each sum then divided by its length (np.linalg.norm's x, y, z)."""
    for k in range(3):
        for t in range(len(faces)):
            v = faces[t, k]
            vn[v, 0] += fn[t, 0]
            vn[v, 1] += fn[t, 1]
            vn[v, 2] += fn[t, 2]
    for v in range(len(vn)):
        length = max(np.sqrt(vn[v, 0] * vn[v, 0] + vn[v, 1] * vn[v, 1] + vn[v, 2] * vn[v, 2]), 1e-30)
        vn[v, 0], vn[v, 1], vn[v, 2] = vn[v, 0] / length, vn[v, 1] / length, vn[v, 2] / length


def vertex_normals_reference(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``vertex_normals`` with numpy: np.add.at over the three corners in turn, as one bincount per axis."""
    fn = face_normals(vertices, faces, normalize=False)
    index, values = np.asarray(faces).T.reshape(-1), np.tile(fn, (3, 1))
    vn = np.stack(
        [np.bincount(index, weights=values[:, d], minlength=len(vertices)) for d in range(3)], axis=1
    )
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-30)


def edges(faces: np.ndarray) -> np.ndarray:
    """Directed half-edges ``(3F, 2)`` in face order (edge k of face f is row 3f + k)."""
    return np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)


def unique_edges(faces: np.ndarray) -> np.ndarray:
    """Undirected edges ``(E, 2)``, each once with the smaller index first."""
    e = np.sort(edges(faces), axis=1)
    return np.unique(e, axis=0)


def edge_lengths(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Lengths ``(E,)`` of the undirected edges."""
    e = unique_edges(faces)
    return np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)


def boundary_edges(faces: np.ndarray) -> np.ndarray:
    """Directed boundary half-edges ``(B, 2)``: half-edges whose twin does not exist."""
    he = edges(faces)
    key = he[:, 0].astype(np.int64) * (faces.max() + 1) + he[:, 1]
    twin = he[:, 1].astype(np.int64) * (faces.max() + 1) + he[:, 0]
    return he[~np.isin(twin, key)]


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Boundary loops as ordered vertex index arrays, following face orientation.

    Raises ValueError if the boundary is not a disjoint union of simple loops
    (a vertex with two outgoing boundary edges means a non-manifold boundary).
    """
    be = boundary_edges(faces)
    nxt: dict[int, int] = {}
    for a, b in be:
        if int(a) in nxt:
            raise ValueError(f"non-manifold boundary at vertex {int(a)}")
        nxt[int(a)] = int(b)
    loops, seen = [], set()
    for start in nxt:
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen:
            seen.add(v)
            loop.append(v)
            if v not in nxt:
                raise ValueError(f"open boundary chain at vertex {v}")
            v = nxt[v]
        if v != start:
            raise ValueError(f"open boundary chain at vertex {start}")
        loops.append(np.array(loop, dtype=np.int64))
    return loops


def is_edge_manifold(faces: np.ndarray) -> bool:
    """Every undirected edge has one or two faces, and no directed half-edge repeats
    (a repeat means two faces disagree on orientation or an edge has > 2 faces)."""
    he = edges(faces)
    if len(np.unique(he, axis=0)) != len(he):
        return False
    _, counts = np.unique(np.sort(he, axis=1), axis=0, return_counts=True)
    return bool(np.all(counts <= 2))


def connected_components(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Component label ``(V,)`` of every vertex (isolated vertices get their own)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components as cc

    e = unique_edges(faces)
    adj = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_vertices, n_vertices))
    return cc(adj, directed=False)[1]


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Signed enclosed volume (positive for a closed, outward-oriented mesh)."""
    v = vertices[faces]
    return float(np.einsum("ij,ij->i", np.cross(v[:, 0], v[:, 1]), v[:, 2]).sum() / 6.0)


def graph_laplacian(faces: np.ndarray, n_vertices: int):
    """The uniform graph Laplacian ``(V, V)`` (scipy CSR: degree minus adjacency) of a triangle mesh."""
    import scipy.sparse as sp

    i = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]])
    j = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]])
    adjacency = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n_vertices, n_vertices)).tocsr()
    adjacency = ((adjacency + adjacency.T) > 0).astype(np.float64)
    return (sp.diags(np.asarray(adjacency.sum(axis=1)).ravel()) - adjacency).tocsr()
