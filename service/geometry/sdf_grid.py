"""The mean body's signed distance on a regular grid, interpolated trilinearly (numpy only).

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
        interpolant inside the grid, the exact one where ``fallback`` answers."""
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
