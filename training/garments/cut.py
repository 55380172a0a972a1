"""Cutting triangle meshes along the zero set of a per-vertex scalar (openings, hems).

Cuts are exact on the piecewise-linear interpolation of the scalar, so an opening is a
clean loop on the surface rather than a jagged row of whole triangles.
"""

from __future__ import annotations

import numpy as np

from service.geometry.mesh import check_mesh, connected_components


def clip_mesh(vertices: np.ndarray, faces: np.ndarray, values: np.ndarray, eps: float = 1e-9):
    """Keep the part of the mesh where the linearly interpolated ``values`` are <= 0.

    vertices: (V, 3) float; faces: (F, 3) int; values: (V,) float.
    Returns (vertices (V', 3), faces (F', 3)) with new vertices on crossing edges; unused
    vertices are dropped. Values within eps of 0 snap to 0: such a vertex is kept and is itself
    the crossing point of its edges, so a cut through vertices leaves no slivers.
    """
    check_mesh(vertices, faces)
    values = np.asarray(values, dtype=np.float64)
    if values.shape != (len(vertices),):
        raise ValueError(f"values must be ({len(vertices)},), got {values.shape}")
    values = np.where(np.abs(values) < eps, 0.0, values)
    inside = values <= 0
    new_vertices = [vertices]
    edge_vertex: dict[tuple[int, int], int] = {}
    count = len(vertices)

    def crossing(a: int, b: int) -> int:
        nonlocal count
        if values[a] == 0.0:
            return a
        if values[b] == 0.0:
            return b
        key = (a, b) if a < b else (b, a)
        if key not in edge_vertex:
            t = values[key[0]] / (values[key[0]] - values[key[1]])
            new_vertices.append(vertices[key[0]] + t * (vertices[key[1]] - vertices[key[0]]))
            edge_vertex[key] = count
            count += 1
        return edge_vertex[key]

    n_in = inside[faces].sum(axis=1)
    out_faces = [faces[n_in == 3]]
    extra = []
    for face in faces[(n_in == 1) | (n_in == 2)]:
        ins = inside[face]
        # Rotate so the odd-one-out vertex comes first, preserving orientation.
        odd = int(np.flatnonzero(ins == (ins.sum() == 1))[0])
        a, b, c = face[odd], face[(odd + 1) % 3], face[(odd + 2) % 3]
        ab, ac = crossing(a, b), crossing(a, c)
        if inside[a]:  # one vertex kept: a small triangle
            extra.append((a, ab, ac))
        else:  # two kept: a quad b, c, ac, ab split in two
            extra.append((ab, b, c))
            extra.append((ab, c, ac))
    if extra:
        out_faces.append(np.array(extra, dtype=faces.dtype))
    all_vertices = np.concatenate([np.atleast_2d(x) for x in new_vertices])
    out = np.concatenate(out_faces)
    # a triangle with a vertex on the cut can collapse to a repeated index: it had no area
    degenerate = (out[:, 0] == out[:, 1]) | (out[:, 1] == out[:, 2]) | (out[:, 2] == out[:, 0])
    return compact(all_vertices, out[~degenerate])


def compact(vertices: np.ndarray, faces: np.ndarray):
    """Drop unreferenced vertices and renumber faces. Returns (vertices, faces)."""
    used = np.unique(faces)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[faces]


def largest_component(vertices: np.ndarray, faces: np.ndarray):
    """The connected component with the most faces. Returns (vertices, faces)."""
    labels = connected_components(faces, len(vertices))
    return _keep_label(vertices, faces, labels, np.bincount(labels[faces[:, 0]]).argmax())


def component_near(vertices: np.ndarray, faces: np.ndarray, point: np.ndarray):
    """The connected component holding the vertex closest to ``point`` (3,).

    A garment keeps the piece around a joint rather than the largest one: after the neck cut
    the head's offset surface can be as large as a small garment. Returns (vertices, faces).
    """
    labels = connected_components(faces, len(vertices))
    return _keep_label(vertices, faces, labels, labels[np.argmin(np.linalg.norm(vertices - point, axis=1))])


def _keep_label(vertices, faces, labels, keep):
    return compact(vertices, faces[labels[faces[:, 0]] == keep])
