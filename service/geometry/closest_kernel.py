"""Compiled point-triangle test (numba): Ericson's test (``closest.closest_on_triangles``) for one
point and one triangle, written out with the same operations in the same order, so that the compiled
searches built on it (``bvh_kernel``; the body map's ``canonical_kernel``) answer as the numpy
references bit for bit (tested). ``bounding_spheres`` bounds triangles for the body map's screening.

Compiled on first use and cached on disk (``cache=True``: next to this file, or in
``NUMBA_CACHE_DIR``; the container image compiles it at build time).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def _safe(num: float, den: float) -> float:
    return num / (den if abs(den) > 1e-30 else 1e-30)


@njit(cache=True, nogil=True, inline="always")
def _clip01(x: float) -> float:
    # np.clip(x, 0, 1): NaN stays NaN
    return 0.0 if x < 0.0 else (1.0 if x > 1.0 else x)


@njit(cache=True, nogil=True)
def barycentric(px, py, pz, a, b, c, out):
    """``closest_on_triangles`` for one point and one triangle (a, b, c: (3,) arrays) into ``out (3,)``,
    the same floating-point operations in the same order."""
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    apx, apy, apz = px - a[0], py - a[1], pz - a[2]
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    bpx, bpy, bpz = px - b[0], py - b[1], pz - b[2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    cpx, cpy, cpz = px - c[0], py - c[1], pz - c[2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    # The reference applies the regions from the face to the vertices, each overriding the last;
    # here the last one that holds is taken directly.
    if d1 <= 0 and d2 <= 0:
        out[0], out[1], out[2] = 1.0, 0.0, 0.0
    elif d3 >= 0 and d4 <= d3:
        out[0], out[1], out[2] = 0.0, 1.0, 0.0
    elif d6 >= 0 and d5 <= d6:
        out[0], out[1], out[2] = 0.0, 0.0, 1.0
    elif vc <= 0 and d1 >= 0 and d3 <= 0:
        t = _clip01(_safe(d1, d1 - d3))
        out[0], out[1], out[2] = 1 - t, t, 0.0
    elif vb <= 0 and d2 >= 0 and d6 <= 0:
        t = _clip01(_safe(d2, d2 - d6))
        out[0], out[1], out[2] = 1 - t, 0.0, t
    elif va <= 0 and (d4 - d3) >= 0 and (d5 - d6) >= 0:
        t = _clip01(_safe(d4 - d3, (d4 - d3) + (d5 - d6)))
        out[0], out[1], out[2] = 0.0, 1 - t, t
    else:
        den = va + vb + vc
        v, t = _safe(vb, den), _safe(vc, den)
        out[0], out[1], out[2] = 1 - v - t, v, t


@njit(cache=True, nogil=True, inline="always")
def closest_on_corners(px, py, pz, a, b, c, w):
    """(distance, closest point x, y, z) of point p on triangle abc (``(3,)`` arrays), its barycentric
    coordinates into ``w (3,)``: the reference's ``closest_on_triangles``, einsum and norm, in their
    order."""
    barycentric(px, py, pz, a, b, c, w)
    qx = w[0] * a[0] + w[1] * b[0] + w[2] * c[0]
    qy = w[0] * a[1] + w[1] * b[1] + w[2] * c[1]
    qz = w[0] * a[2] + w[1] * b[2] + w[2] * c[2]
    dx, dy, dz = px - qx, py - qy, pz - qz
    return np.sqrt(dx * dx + dy * dy + dz * dz), qx, qy, qz


@njit(cache=True, nogil=True, inline="always")
def closest_on(px, py, pz, vertices, faces, f, w):
    """``closest_on_corners`` for triangle ``f`` of ``faces`` over ``vertices``."""
    a, b, c = vertices[faces[f, 0]], vertices[faces[f, 1]], vertices[faces[f, 2]]
    return closest_on_corners(px, py, pz, a, b, c, w)


@njit(cache=True, nogil=True)
def bounding_spheres(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(F, 4)``: each triangle's centroid and its distance to the farthest corner, grown by a
    relative 1e-9 so that rounding in the test never rules out the closest triangle."""
    out = np.empty((len(faces), 4))
    for f in range(len(faces)):
        for d in range(3):
            out[f, d] = (vertices[faces[f, 0], d] + vertices[faces[f, 1], d] + vertices[faces[f, 2], d]) / 3.0
        r2 = 0.0
        for corner in range(3):
            v = faces[f, corner]
            dx, dy, dz = vertices[v, 0] - out[f, 0], vertices[v, 1] - out[f, 1], vertices[v, 2] - out[f, 2]
            r2 = max(r2, dx * dx + dy * dy + dz * dz)
        out[f, 3] = np.sqrt(r2) * (1 + 1e-9) + 1e-12
    return out
