"""Small hand-made meshes shared by the geometry tests."""

import numpy as np


def grid_mesh(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit square in z = 0 split into n x n quads, two triangles each, normals +z."""
    x, y = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    idx = np.arange(x.size).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return vertices, np.concatenate([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)])


def sheet(n: int, size: float, z):
    """A square sheet ``size`` m wide of ``grid_mesh(n)``, centred on the origin, at heights ``z(v)``:
    (vertices (V, 3), faces (F, 3))."""
    v, f = grid_mesh(n)
    v = (v - [0.5, 0.5, 0]) * [size, size, 0]
    v[:, 2] = z(v)
    return v, f
