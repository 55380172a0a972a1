"""Tileable fabric textures made by code: jersey knit, rib knit, denim and twill.

Each weave is a periodic height field over one tile (the texture wraps, so every pattern and every
noise term has an integer number of periods across the image); the base colour is the yarn colour
shaded by that height and by slow yarn-to-yarn variation, and the normal map is the height field's
slope (tangent space, +Z out of the cloth). Small (``SIZE`` pixels a side) so that an outfit's GLB
stays light; the tile size in metres says how large a tile is on the garment.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

Weave = Literal["jersey", "rib", "denim", "twill"]
SIZE = 128


@dataclass(frozen=True)
class Fabric:
    """A garment's cloth: weave, yarn colour RGB in [0, 1], tile size (m), glTF roughness."""

    weave: Weave
    color: tuple[float, float, float]
    tile: float
    roughness: float = 0.9


def periodic_noise(rng: np.random.Generator, size: int, scale: float) -> np.ndarray:
    """(size, size) noise in [-1, 1] that tiles: white noise low-passed in Fourier space."""
    k = np.fft.fftfreq(size) * size
    radius = np.hypot(*np.meshgrid(k, k, indexing="ij"))
    spectrum = np.fft.fft2(rng.normal(size=(size, size))) * np.exp(-((radius / scale) ** 2))
    field = np.fft.ifft2(spectrum).real
    return field / max(np.abs(field).max(), 1e-12)


def height_field(weave: Weave, size: int = SIZE, seed: int = 0) -> np.ndarray:
    """(size, size) height in [0, 1] of one tile; rows are the image's v, columns its u."""
    rng = np.random.default_rng(seed)
    v, u = np.meshgrid(np.arange(size) / size, np.arange(size) / size, indexing="ij")
    if weave == "jersey":  # columns of V-shaped stitches: 16 wales, 16 courses a tile
        wale = (u * 16) % 1.0
        course = (v * 16 + 0.5 * np.abs(wale - 0.5)) % 1.0
        h = np.sin(np.pi * wale) ** 2 * np.sin(np.pi * course) ** 0.5
    elif weave == "rib":  # 1x1 rib: raised wales
        h = 0.5 + 0.5 * np.cos(2 * np.pi * 12 * u)
    else:  # twill lines at 45 degrees; denim's are finer
        lines = 24 if weave == "denim" else 16
        h = 0.5 + 0.5 * np.cos(2 * np.pi * lines * (u + v))
    h = h + 0.08 * periodic_noise(rng, size, 24.0)
    return (h - h.min()) / max(np.ptp(h), 1e-12)


def base_color(fabric: Fabric, seed: int = 0) -> np.ndarray:
    """(SIZE, SIZE, 3) RGB in [0, 1]: the yarn colour shaded by the weave."""
    h = height_field(fabric.weave, seed=seed)
    yarn = 1.0 + 0.05 * periodic_noise(np.random.default_rng(seed + 1), SIZE, 4.0)
    color = np.asarray(fabric.color)
    if fabric.weave == "denim":  # indigo warp over a pale weft, which shows in the twill's valleys
        weft = np.array([0.82, 0.83, 0.86])
        rgb = h[..., None] * color + (1 - h[..., None]) * (0.6 * color + 0.4 * weft)
    else:
        rgb = color * (0.78 + 0.22 * h[..., None])
    return np.clip(rgb * yarn[..., None], 0.0, 1.0)


def normal_map(fabric: Fabric, strength: float = 2.0, seed: int = 0) -> np.ndarray:
    """(SIZE, SIZE, 3) tangent-space normals encoded in [0, 1] (glTF: +X along u, +Y along -v)."""
    h = height_field(fabric.weave, seed=seed) * strength
    du = (np.roll(h, -1, axis=1) - np.roll(h, 1, axis=1)) / 2
    dv = (np.roll(h, -1, axis=0) - np.roll(h, 1, axis=0)) / 2
    n = np.stack([-du, dv, np.ones_like(h)], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True) * 0.5 + 0.5
