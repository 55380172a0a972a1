"""The mean body's signed distance on a regular grid, interpolated trilinearly (numpy; numba for the lookups).

In canonical space every body is the mean body (paper 4.1), so its signed distance is one fixed field:
sampled once offline (``export.body_sdf``) from the exact closest-point query it replaces, it costs a
few array lookups per point instead of ~10 us of triangle tests. The interpolation error is about
spacing^2 / (8 R) for a surface of curvature radius R: 0.1 mm on a 4 cm arm at 6 mm spacing
(``benchmarks/body_sdf.py`` measures it against the exact distance). Points outside the grid, or where
the stored distance is clipped below -clip, go to the exact query (``fallback``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

# fallback(x (P, 3)) -> (signed distance (P,), gradient (P, 3))
Fallback = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass
class SdfGrid:
    origin: np.ndarray  # (3,) m, the position of values[0, 0, 0]
    spacing: float  # m
    values: np.ndarray  # (nx, ny, nz) float32 signed distance, clipped to +-clip
    clip: float  # m

    @classmethod
    def sample(cls, sdf: Fallback, lo: np.ndarray, hi: np.ndarray, spacing: float, clip: float) -> SdfGrid:
        """Grid over the box ``lo``..``hi`` (3,) sampled with the exact ``sdf``."""
        shape = np.ceil((np.asarray(hi) - lo) / spacing).astype(int) + 1
        axes = [lo[d] + spacing * np.arange(shape[d]) for d in range(3)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        values = np.concatenate([sdf(grid[s : s + 50_000])[0] for s in range(0, len(grid), 50_000)])
        return cls(
            np.asarray(lo, float),
            spacing,
            np.clip(values, -clip, clip).reshape(shape).astype(np.float32),
            clip,
        )

    def save(self, path: Path) -> None:
        np.savez_compressed(
            path,
            origin=self.origin,
            spacing=self.spacing,
            clip=self.clip,
            values=self.values.astype(np.float16),
        )

    @classmethod
    def load(cls, path: Path) -> SdfGrid:
        with np.load(path) as z:
            return cls(z["origin"], float(z["spacing"]), z["values"].astype(np.float32), float(z["clip"]))

    def __call__(self, x: np.ndarray, fallback: Fallback) -> tuple[np.ndarray, np.ndarray]:
        """(signed distance (P,), its gradient (P, 3)) at ``x (P, 3)``: the gradient of the trilinear
        interpolant inside the grid, the exact one where ``fallback`` answers. One compiled loop per
        point (``_trilinear``), ``call_reference`` bit for bit: the fit asks for every garment vertex of
        a request, where the numpy version's (P, 8) temporaries cost ~1 us a point."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        d, grad = np.empty(len(x)), np.empty_like(x)
        exact = np.empty(len(x), dtype=np.bool_)
        origin = self.origin.astype(np.float64)
        _trilinear(x, origin, float(self.spacing), self.values, float(self.clip), d, grad, exact)
        if exact.any():
            d[exact], grad[exact] = fallback(x[exact])
        return d, grad

    def call_reference(self, x: np.ndarray, fallback: Fallback) -> tuple[np.ndarray, np.ndarray]:
        """``__call__`` in numpy arrays."""
        x = np.asarray(x, dtype=np.float64)
        u = (x - self.origin) / self.spacing
        top = np.array(self.values.shape) - 1
        cell = np.floor(u).astype(np.int64)
        inside = np.all((cell >= 0) & (cell < top), axis=1)
        cell = np.clip(cell, 0, top - 1)
        t = np.clip(u - cell, 0.0, 1.0)  # (P, 3)
        v = self.values
        i, j, k = cell.T
        c = np.stack([v[i + a, j + b, k + e] for a in (0, 1) for b in (0, 1) for e in (0, 1)], 1)  # (P, 8)
        c = c.reshape(-1, 2, 2, 2).astype(np.float64)
        tx, ty, tz = t[:, 0, None, None], t[:, 1, None], t[:, 2]
        cx = c[:, 0] * (1 - tx) + c[:, 1] * tx  # (P, 2, 2) over (y, z)
        cy = cx[:, 0] * (1 - ty) + cx[:, 1] * ty  # (P, 2) over z
        d = cy[:, 0] * (1 - tz) + cy[:, 1] * tz
        grad = np.empty_like(x)
        grad[:, 2] = cy[:, 1] - cy[:, 0]
        dy = cx[:, 1] - cx[:, 0]  # (P, 2) over z
        grad[:, 1] = dy[:, 0] * (1 - tz) + dy[:, 1] * tz
        dx = c[:, 1] - c[:, 0]  # (P, 2, 2)
        dxy = dx[:, 0] * (1 - ty) + dx[:, 1] * ty
        grad[:, 0] = dxy[:, 0] * (1 - tz) + dxy[:, 1] * tz
        grad /= self.spacing
        # Deep inside (a corner clipped at -clip) the interpolant is not the distance and its gradient
        # vanishes: ask the exact query. Far outside (+clip) it only says "far", which is all the
        # untangling needs to know of a body farther than clip.
        exact = ~inside | (c.reshape(len(x), 8).min(axis=1) <= -self.clip * 0.999)
        if exact.any():
            d[exact], grad[exact] = fallback(x[exact])
        return d, grad


@njit(cache=True, nogil=True)
def _trilinear(x, origin, spacing, values, clip, d, grad, exact):
    """``SdfGrid.call_reference``'s interpolation, point by point, in its operations and order; ``exact``
    marks the points for the fallback (their ``d``, ``grad`` are then left to it)."""
    nx, ny, nz = values.shape
    top = (nx - 1, ny - 1, nz - 1)
    cell = np.empty(3, dtype=np.int64)
    t = np.empty(3)
    c = np.empty((2, 2, 2))
    for p in range(len(x)):
        inside = True
        for a in range(3):
            u = (x[p, a] - origin[a]) / spacing
            ci = np.int64(np.floor(u))
            inside = inside and u == u and 0 <= ci < top[a]  # a NaN point goes to the fallback
            ci = min(max(ci, 0), top[a] - 1)
            cell[a] = ci
            t[a] = min(max(u - ci, 0.0), 1.0)
        lowest = np.inf
        for a in range(2):
            for b in range(2):
                for e in range(2):
                    c[a, b, e] = np.float64(values[cell[0] + a, cell[1] + b, cell[2] + e])
                    lowest = min(lowest, c[a, b, e])
        tx, ty, tz = t[0], t[1], t[2]
        cx00 = c[0, 0, 0] * (1 - tx) + c[1, 0, 0] * tx  # cx[y, z]
        cx01 = c[0, 0, 1] * (1 - tx) + c[1, 0, 1] * tx
        cx10 = c[0, 1, 0] * (1 - tx) + c[1, 1, 0] * tx
        cx11 = c[0, 1, 1] * (1 - tx) + c[1, 1, 1] * tx
        cy0 = cx00 * (1 - ty) + cx10 * ty  # cy[z]
        cy1 = cx01 * (1 - ty) + cx11 * ty
        d[p] = cy0 * (1 - tz) + cy1 * tz
        grad[p, 2] = (cy1 - cy0) / spacing
        dy0, dy1 = cx10 - cx00, cx11 - cx01
        grad[p, 1] = (dy0 * (1 - tz) + dy1 * tz) / spacing
        dxy0 = (c[1, 0, 0] - c[0, 0, 0]) * (1 - ty) + (c[1, 1, 0] - c[0, 1, 0]) * ty
        dxy1 = (c[1, 0, 1] - c[0, 0, 1]) * (1 - ty) + (c[1, 1, 1] - c[0, 1, 1]) * ty
        grad[p, 0] = (dxy0 * (1 - tz) + dxy1 * tz) / spacing
        exact[p] = not inside or lowest <= -clip * 0.999
