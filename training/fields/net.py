"""The neural field g(x, beta) = (f, h) of one garment or the body (paper 3.1, eq. 1-5), in torch.

x (canonical space, m) is normalised by the garment's padded bounding box and encoded with Fourier
features [x, sin(2 pi B x), cos(2 pi B x)] (Tancik et al. 2020; B ~ N(0, sigma^2), fixed), beta is
normalised over the supported box, and an MLP with SiLU activations (smooth, so that its input
gradients are smooth too) outputs (f, h) / OUTPUT_SCALE.

``with_gradient`` returns f, h and their x-gradients in reverse mode: after the values pass, the
cotangents of f and h go back through the layers as one (2, P, W) tensor, one GEMM per layer (forward
mode, the earlier form, needs three tangents). Training uses it for the
gradient losses and the ONNX export runs the same code, so the exported gradient graph is the trained
one. The beta part of the first layer is computed once per call (beta is one shape per request).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

BETA_LOW = (0.0, 0.12, 0.0)
BETA_HIGH = (1.0, 0.72, 1.0)
OUTPUT_SCALE = 0.1  # m per network output unit
SIGMA_PER_METRE = 2.2
"""Frequencies per metre the Fourier features resolve at least (``fourier_sigma``)."""


def fourier_sigma(half_extent: float) -> float:
    """sigma for a box of this half extent (m): 1 per half box (tuned on the T-shirt, 0.44 m), and
    at least SIGMA_PER_METRE cycles per metre, so that a jacket or the body (0.66 m, 1.0 m) resolves
    folds as finely as the T-shirt (at sigma 1 their f errors were 2.6 and 1.8 mm)."""
    return max(1.0, SIGMA_PER_METRE * half_extent)


@dataclass(frozen=True)
class FieldConfig:
    width: int = 96
    """Width of every hidden layer (tshirt at 1,000 steps, f / h mm: width 64 3.4 / 3.2 at sigma 2,
    2.3 / 2.0 at sigma 1; width 96 at sigma 1 2.0 / 1.6; width 128 at sigma 2 2.5 / 2.2)."""
    depth: int = 3
    """Number of hidden layers."""
    fourier: int = 32
    """Number of Fourier frequencies; 0 feeds x alone (the ablation without Fourier features)."""
    sigma: float = 1.0
    """Standard deviation of the frequencies, cycles per unit of normalised x (half the box); at
    1,000 steps sigma 0.5 / 1 / 2 / 5 gave f errors 2.4 / 2.3 / 3.4 / 5.9 mm (width 64)."""
    grad_weight: float = 0.01
    """lambda of eq. 1 (m): weight of the L1 gradient losses; 0 is the ablation without them."""
    steps: int = 3000
    batch: int = 4096
    lr: float = 3e-3
    """Adam learning rate, cosine-decayed to 1 % of it."""
    n_betas: int = 96
    """Training body shapes (Sobol over the supported box)."""
    points_per_beta: int = 8192
    seed: int = 0


class FieldNet(torch.nn.Module):
    """``forward(x (P, 3), beta (1, 3)) -> (f (P,), h (P,))``; ``with_gradient`` adds (P, 3) twice."""

    def __init__(self, config: FieldConfig, centre: np.ndarray, half_extent: float):
        super().__init__()
        self.config = config
        g = torch.Generator().manual_seed(config.seed)
        freqs = torch.randn(config.fourier, 3, generator=g, dtype=torch.float64) * config.sigma
        self.register_buffer("freqs", (2 * math.pi * freqs).float())  # (m, 3) angular
        self.register_buffer("centre", torch.as_tensor(np.asarray(centre), dtype=torch.float32))
        self.register_buffer("inv_extent", torch.tensor(1.0 / half_extent, dtype=torch.float32))
        low, high = torch.tensor(BETA_LOW), torch.tensor(BETA_HIGH)
        self.register_buffer("beta_shift", (low + high) / 2)
        self.register_buffer("beta_scale", 2 / (high - low))
        n_in = 3 + 2 * config.fourier
        dims = [n_in] + [config.width] * config.depth
        self.first = torch.nn.Linear(n_in, config.width)
        self.first_beta = torch.nn.Linear(3, config.width, bias=False)
        self.hidden = torch.nn.ModuleList(
            torch.nn.Linear(a, b) for a, b in zip(dims[1:-1], dims[2:], strict=True)
        )
        self.out = torch.nn.Linear(config.width, 2)

    def _features(self, x):
        xn = (x - self.centre) * self.inv_extent  # (P, 3)
        proj = xn @ self.freqs.T  # (P, m)
        return xn, proj

    def _first_bias(self, beta):
        return self.first_beta((beta - self.beta_shift) * self.beta_scale) + self.first.bias  # (1, W)

    def forward(self, x, beta):
        xn, proj = self._features(x)
        features = torch.cat([xn, torch.sin(proj), torch.cos(proj)], 1)
        a = torch.nn.functional.silu(features @ self.first.weight.T + self._first_bias(beta))
        for layer in self.hidden:
            a = torch.nn.functional.silu(layer(a))
        out = self.out(a) * OUTPUT_SCALE
        return out[:, 0], out[:, 1]

    def with_gradient(self, x, beta, h_gradient: bool = True):
        """(f (P,), h (P,), grad f (P, 3), grad h (P, 3)), gradients in reverse mode; without
        ``h_gradient`` only grad f, (f, h, grad f): one cotangent, ~30 % less work (the fit needs
        grad h only where the untangler's blend band makes it count).

        Two cotangents instead of three tangents: 2/3 of forward mode's GEMM work on the hidden
        layers, and no per-layer concatenation (the stacked forward-mode graph this replaced spent
        more time in Concat, Slice and Tile than in its GEMMs).
        """
        m = self.config.fourier
        xn, proj = self._features(x)
        s, c = torch.sin(proj), torch.cos(proj)  # (P, m)
        features = torch.cat([xn, s, c], 1)  # (P, 3 + 2m)
        a, slope = self._silu_and_slope(features @ self.first.weight.T + self._first_bias(beta))
        slopes = [slope]  # silu'(z) of every layer, (P, W)
        for layer in self.hidden:
            a, slope = self._silu_and_slope(layer(a))
            slopes.append(slope)
        out = self.out(a) * OUTPUT_SCALE  # (P, 2)
        # Cotangents d(f, h) / dz of each layer, last to first: (2, P, W), or (1, P, W) for f alone.
        w_out = self.out.weight if h_gradient else self.out.weight[:1]
        g = (w_out * OUTPUT_SCALE)[:, None, :] * slopes[-1]
        for layer, slope in zip(reversed(self.hidden), reversed(slopes[:-1]), strict=True):
            g = (g @ layer.weight) * slope
        # Through the features: d xn / dx = inv_extent, d sin / dx = cos freqs inv_extent, d cos = -sin ...
        g_xn, g_sin, g_cos = (g @ self.first.weight).split([3, m, m], -1)  # (2, P, 3), (2, P, m) twice
        grad = (g_xn + (g_sin * c - g_cos * s) @ self.freqs) * self.inv_extent  # (2, P, 3)
        if not h_gradient:
            return out[:, 0], out[:, 1], grad[0]
        return out[:, 0], out[:, 1], grad[0], grad[1]

    @staticmethod
    def _silu_and_slope(z):
        """(silu(z), silu'(z)) for z (P, W); silu' = sig (1 + z (1 - sig)) = sig + silu (1 - sig)."""
        sig = torch.sigmoid(z)
        a = z * sig
        return a, sig + a * (1 - sig)
