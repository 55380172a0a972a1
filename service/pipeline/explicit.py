"""Explicit garment model (paper 4.1): beta -> canonical garment vertices X(beta), numpy only.

X(beta) = mean + sum_k c_k(beta) * basis_k, with the PCA basis of the canonical drapes and the
coefficients c(beta) from a small tanh MLP of the normalised shape. This is the reference the
ONNX export is checked against; the world-space garment is X + B~s(X, beta) (service.pipeline.canonical).
Files: ``models/explicit/<garment id>.npz`` written by ``python -m training.explicit``.
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


@dataclass
class ExplicitModel:
    garment_id: str
    mean: np.ndarray  # (V, 3) float32 canonical mean drape
    basis: np.ndarray  # (K, V, 3) float16 orthonormal PCA directions (flattened)
    beta_shift: np.ndarray  # (3,) input normalisation: (beta - shift) / scale
    beta_scale: np.ndarray  # (3,)
    weights: list[np.ndarray]  # per layer (out, in) float32
    biases: list[np.ndarray]  # per layer (out,) float32

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
        return self.mean.astype(np.float64) + np.tensordot(c, self.basis.astype(np.float64), axes=1)

    def save(self, path: Path) -> Path:
        arrays = {
            "mean": self.mean,
            "basis": self.basis,
            "beta_shift": self.beta_shift,
            "beta_scale": self.beta_scale,
        }
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            arrays[f"w{i}"], arrays[f"b{i}"] = w, b
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, garment_id=self.garment_id, **arrays)
        return path

    @classmethod
    def load(cls, garment_id: str, directory: Path | None = None) -> ExplicitModel:
        path = Path(directory or models_dir() / "explicit") / f"{garment_id}.npz"
        with np.load(path) as z:
            n = sum(1 for k in z.files if k.startswith("w"))
            return cls(
                str(z["garment_id"]), z["mean"], z["basis"], z["beta_shift"], z["beta_scale"],
                [z[f"w{i}"] for i in range(n)], [z[f"b{i}"] for i in range(n)],
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
