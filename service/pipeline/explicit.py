"""Explicit garment model (paper 4.1): beta -> canonical garment vertices X(beta), numpy only.

q(beta) = mean + sum_k c_k(beta) * basis_k, with the PCA basis of the encoded canonical drapes and
the coefficients c(beta) from a small tanh MLP of the normalised shape. This is the reference the
ONNX export is checked against; the world-space garment is X + B~s(X, beta) (service.pipeline.canonical).
Files: ``models/explicit/<garment id>.npz`` written by ``python -m training.explicit``.

Body-offset coordinates (``anchor`` and ``frame`` set; issue 21): each vertex is stored in the frame
of a fixed point of the mean body, q = (s1, s2, u) with s the tangential offset and u = encode(d) of
its height d above the tangent plane there. ``encode`` is the identity beyond ``soft`` (5 mm) and
logarithmic below, so every decoded d is > 0: a prediction for a body shape the dataset does not
cover (the corners of the box) can come arbitrarily close to the body but not sink into it, wherever
the body is convex around the anchor. Canonical space has one body for every shape, and the
canonical-to-world map keeps distances to it (measured: the share of vertices inside the body is the
same in both), so outside in canonical space is outside on the shopper's body. Without ``anchor``
(models trained before), q is X itself.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from service.process.paths import models_dir

# ONNX contract of the exported model (export/explicit.py): beta (B, 3) -> canonical vertices (B, V, 3)
ONNX_INPUT, ONNX_OUTPUT, ONNX_BATCH_AXIS = "beta", "vertices", "shapes"
ONNX_OPSET = 17
ONNX_TOLERANCE = 1e-5  # m: float32 graph against this float64 reference
SOFT = 0.005  # m: below this height above its anchor's tangent plane a vertex's height is stored as a log


def encode_height(d: np.ndarray, soft: float = SOFT) -> np.ndarray:
    """u (same shape as d > 0): d beyond ``soft``, soft (1 + log(d / soft)) below (C1 at soft)."""
    d = np.asarray(d, dtype=np.float64)
    return np.where(d >= soft, d, soft * (1.0 + np.log(np.maximum(d, 1e-12) / soft)))


def decode_height(u: np.ndarray, soft: float = SOFT) -> np.ndarray:
    """The inverse of ``encode_height``: > 0 for every u."""
    u = np.asarray(u, dtype=np.float64)
    return np.where(u >= soft, u, soft * np.exp(np.minimum(u - soft, 0.0) / soft))


@dataclass
class ExplicitModel:
    garment_id: str
    mean: np.ndarray  # (V, 3) float32 mean of the coordinates q over the training drapes
    basis: np.ndarray  # (K, V, 3) float16 orthonormal PCA directions (flattened)
    beta_shift: np.ndarray  # (3,) input normalisation: (beta - shift) / scale
    beta_scale: np.ndarray  # (3,)
    weights: list[np.ndarray]  # per layer (out, in) float32
    biases: list[np.ndarray]  # per layer (out,) float32
    anchor: np.ndarray | None = None  # (V, 3) float32 points of the mean body, or None: q is X
    frame: np.ndarray | None = None  # (V, 3, 3) float32 rows t1, t2, n (outward unit normal)
    soft: float = SOFT

    def coefficients(self, betas: np.ndarray) -> np.ndarray:
        """PCA coefficients ``(B, K)`` for betas ``(B, 3)``."""
        betas = np.asarray(betas, dtype=np.float64)
        if betas.ndim != 2 or betas.shape[1] != 3:
            raise ValueError(f"betas must be (B, 3), got {betas.shape}")
        h = (betas - self.beta_shift) / self.beta_scale
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            h = h @ w.T.astype(np.float64) + b
            if i < len(self.weights) - 1:
                h = np.tanh(h)
        return h

    def canonical(self, beta: np.ndarray) -> np.ndarray:
        """Canonical garment vertices ``(V, 3)`` float64 for one beta ``(3,)``."""
        c = self.coefficients(np.asarray(beta, dtype=np.float64)[None])[0]
        q = self.mean.astype(np.float64) + np.tensordot(c, self.basis.astype(np.float64), axes=1)
        return self.decode(q)

    def decode(self, q: np.ndarray) -> np.ndarray:
        """Canonical vertices ``(V, 3)`` of coordinates ``q (V, 3)``."""
        if self.anchor is None:
            return q
        local = np.column_stack([q[:, 0], q[:, 1], decode_height(q[:, 2], self.soft)])
        return self.anchor.astype(np.float64) + np.einsum("vk,vkx->vx", local, self.frame.astype(np.float64))

    def encode(self, x: np.ndarray) -> np.ndarray:
        """Coordinates ``q (V, 3)`` of canonical vertices ``x (V, 3)`` (heights floored at 0.1 mm)."""
        if self.anchor is None:
            return np.asarray(x, dtype=np.float64)
        local = np.einsum("vkx,vx->vk", self.frame.astype(np.float64), x - self.anchor.astype(np.float64))
        height = encode_height(np.maximum(local[:, 2], 1e-4), self.soft)
        return np.column_stack([local[:, 0], local[:, 1], height])

    def save(self, path: Path) -> Path:
        arrays = {
            "mean": self.mean,
            "basis": self.basis,
            "beta_shift": self.beta_shift,
            "beta_scale": self.beta_scale,
        }
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            arrays[f"w{i}"], arrays[f"b{i}"] = w, b
        if self.anchor is not None:
            arrays |= {"anchor": self.anchor, "frame": self.frame, "soft": np.float64(self.soft)}
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, garment_id=self.garment_id, **arrays)
        return path

    @classmethod
    def load(cls, garment_id: str, directory: Path | None = None) -> ExplicitModel:
        path = Path(directory or models_dir() / "explicit") / f"{garment_id}.npz"
        with np.load(path) as z:
            n = sum(1 for k in z.files if k.startswith("w"))
            offsets = {}
            if "anchor" in z:
                offsets = {"anchor": z["anchor"], "frame": z["frame"], "soft": float(z["soft"])}
            return cls(
                str(z["garment_id"]), z["mean"], z["basis"], z["beta_shift"], z["beta_scale"],
                [z[f"w{i}"] for i in range(n)], [z[f"b{i}"] for i in range(n)], **offsets,
            )  # fmt: skip


class ExplicitOnnx:
    """The exported explicit model run by onnxruntime: what the service uses."""

    def __init__(self, garment_id: str, directory: Path | None = None, threads: int = 1):
        from service.process.onnx_session import open_session

        path = Path(directory or models_dir() / "explicit") / f"{garment_id}.onnx"
        self.session = open_session(path, threads)

    def canonical(self, beta: np.ndarray) -> np.ndarray:
        """Canonical garment vertices ``(V, 3)`` float64 for one beta ``(3,)``."""
        b = np.asarray(beta, dtype=np.float32).reshape(1, 3)
        return self.session.run([ONNX_OUTPUT], {ONNX_INPUT: b})[0][0].astype(np.float64)
