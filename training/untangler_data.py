"""Samples of the untangler's inputs (numpy only): f*, h* ``(n, 5) float64`` for body + 4 garment slots.

- ``sample_paper``: the paper's distribution (3.2), f* ~ U(-0.2, 1.5), h* ~ U(-1, 1);
- ``sample_near_zero``: all f* of a sample within a scale log-uniform in [1 mm, 20 cm] of 0;
- ``sample_layered``: outfits, garment k lying d_k outside the body with gaps of -1..2 cm (so layers
  are a few mm apart and sometimes cross), the point near one of the surfaces.

The body's h* is set to -1 by ``sample_batch`` (the operators ignore it). Used for training, the
export check, the tests and ``benchmarks/untangler.py``.
"""

from __future__ import annotations

import numpy as np

from service.pipeline.untangle_onnx import N_SLOTS, PAD_F, PAD_H


def sample_paper(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The paper's distribution: f* ~ U(-0.2, 1.5), h* ~ U(-1, 1)."""
    return rng.uniform(-0.2, 1.5, (n, N_SLOTS)), rng.uniform(-1.0, 1.0, (n, N_SLOTS))


def sample_near_zero(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """f* ~ s U(-1, 1) with a per-sample scale s log-uniform in [1 mm, 20 cm]; h* ~ U(-1, 1)."""
    scale = np.exp(rng.uniform(np.log(1e-3), np.log(0.2), (n, 1)))
    return scale * rng.uniform(-1.0, 1.0, (n, N_SLOTS)), rng.uniform(-1.0, 1.0, (n, N_SLOTS))


def sample_layered(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Outfits: garment k lies d_k outside the body (first gap -0.5..3 cm, then -1..2 cm), the point
    lies near one of the surfaces (log-uniform 0.5 mm..5 cm), each garment f* is perturbed by 2 mm
    (surfaces are not parallel); garments are active with probability 0.85."""
    gaps = np.concatenate([rng.uniform(-0.005, 0.03, (n, 1)), rng.uniform(-0.01, 0.02, (n, N_SLOTS - 2))], 1)
    offset = np.concatenate([np.zeros((n, 1)), np.cumsum(gaps, axis=1)], axis=1)
    near = offset[np.arange(n), rng.integers(0, N_SLOTS, n)]
    body = near + np.exp(rng.uniform(np.log(5e-4), np.log(0.05), n)) * rng.standard_normal(n)
    f = body[:, None] - offset + 0.002 * rng.standard_normal((n, N_SLOTS))
    f[:, 0] = body
    h = np.where(rng.random((n, N_SLOTS)) < 0.85, -1.0, 1.0) * rng.uniform(0.0, 1.0, (n, N_SLOTS))
    return f, h


SAMPLERS = (sample_paper, sample_near_zero, sample_layered)


def pad_unused(rng: np.random.Generator, f: np.ndarray, h: np.ndarray, share: float) -> np.ndarray:
    """Pad the slots past a random outfit size (1..5 layers) in ``share`` of the rows of ``f``, ``h``
    ``(n, 5)``, in place; returns the used-slot mask ``(n, 5) bool``."""
    used = np.ones(f.shape, dtype=bool)
    rows = rng.random(len(f)) < share
    used[rows] = np.arange(N_SLOTS)[None, :] < rng.integers(1, N_SLOTS + 1, rows.sum())[:, None]
    f[~used], h[~used] = PAD_F, PAD_H
    return used


def sample_batch(
    rng: np.random.Generator, n: int, mixture=(0.4, 0.2, 0.4), h_band: float = 0.01, padded: float = 0.3
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(f*, h*, used) ``(n, 5)``: ``mixture`` shares of the three samplers; a tenth of the garment h*
    redrawn within 2 ``h_band`` of 0, where the network blends a garment in; ``padded`` share of the
    rows with unused slots."""
    counts = rng.multinomial(n, mixture)
    parts = [sampler(rng, c) for sampler, c in zip(SAMPLERS, counts, strict=True)]
    f, h = np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
    band = rng.random(h.shape) < 0.1
    h[band] = rng.uniform(-2.0, 2.0, band.sum()) * h_band
    h[:, 0] = -1.0
    return f, h, pad_unused(rng, f, h, padded)
