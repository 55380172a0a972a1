"""Export the explicit garment models to ONNX: ``python -m export.explicit [--out DIR] [ids...]``
(seconds), after ``python -m training.explicit`` wrote their npz files.

The graph is the numpy reference ``service.pipeline.explicit.ExplicitModel`` in torch: normalise beta, the
tanh MLP, then mean + coefficients x basis, with the PCA basis stored float16 (as in the npz) and cast in the
graph, then (body-offset models) the heights decoded and the coordinates put back in canonical space.
Contract (names, batch axis, opset, tolerance) in ``service.pipeline.explicit``; the export runs the
file with onnxruntime on the held-out-like check shapes and raises unless it matches the numpy reference.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np
import torch

from service.pipeline.catalog import load_catalog
from service.pipeline.explicit import (
    ONNX_BATCH_AXIS,
    ONNX_INPUT,
    ONNX_OPSET,
    ONNX_OUTPUT,
    ONNX_TOLERANCE,
    ExplicitModel,
    ExplicitOnnx,
)
from service.process.paths import models_dir
from training.drape.dataset import sample_betas

CHECK_SEED = 11


class ExplicitNet(torch.nn.Module):
    def __init__(self, model: ExplicitModel):
        super().__init__()
        self.register_buffer("shift", torch.tensor(model.beta_shift, dtype=torch.float32))
        self.register_buffer("scale", torch.tensor(model.beta_scale, dtype=torch.float32))
        self.layers = torch.nn.ModuleList()
        for w, b in zip(model.weights, model.biases, strict=True):
            layer = torch.nn.Linear(w.shape[1], w.shape[0])
            layer.weight.data = torch.tensor(w, dtype=torch.float32)
            layer.bias.data = torch.tensor(b, dtype=torch.float32)
            self.layers.append(layer)
        self.register_buffer("mean", torch.tensor(model.mean, dtype=torch.float32).reshape(-1))
        self.register_buffer(
            "basis", torch.tensor(model.basis, dtype=torch.float16).reshape(len(model.basis), -1)
        )
        self.offsets = model.anchor is not None
        if self.offsets:
            self.register_buffer("anchor", torch.tensor(model.anchor, dtype=torch.float32))
            self.register_buffer("frame", torch.tensor(model.frame, dtype=torch.float32))
            self.soft = float(model.soft)

    def forward(self, beta):
        h = (beta - self.shift) / self.scale
        for i, layer in enumerate(self.layers):
            h = layer(h)
            if i < len(self.layers) - 1:
                h = torch.tanh(h)
        q = (self.mean + h @ self.basis.float()).reshape(beta.shape[0], -1, 3)
        if not self.offsets:
            return q
        u = q[..., 2:3]
        # decode_height: exp of a non-positive argument only, so the unused branch never overflows
        low = self.soft * torch.exp(torch.clamp(u - self.soft, max=0.0) / self.soft)
        local = torch.cat([q[..., :2], torch.where(u >= self.soft, u, low)], dim=-1)
        return self.anchor + torch.einsum("bvk,vkx->bvx", local, self.frame)


def export_explicit(garment_id: str, directory: Path | None = None) -> float:
    """Write ``<id>.onnx`` beside ``<id>.npz``; returns the largest deviation (m) from the reference."""
    directory = Path(directory or models_dir() / "explicit")
    model = ExplicitModel.load(garment_id, directory)
    net = ExplicitNet(model).eval()
    betas = sample_betas(8, CHECK_SEED)
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")  # the legacy exporter's deprecation notice
        torch.onnx.export(
            net, (torch.tensor(betas[:2], dtype=torch.float32),), str(directory / f"{garment_id}.onnx"),
            dynamo=False, opset_version=ONNX_OPSET, input_names=[ONNX_INPUT], output_names=[ONNX_OUTPUT],
            dynamic_axes={ONNX_INPUT: {0: ONNX_BATCH_AXIS}, ONNX_OUTPUT: {0: ONNX_BATCH_AXIS}},
        )  # fmt: skip
    onnx_model = ExplicitOnnx(garment_id, directory)
    error = max(float(np.abs(onnx_model.canonical(b) - model.canonical(b)).max()) for b in betas)
    if error > ONNX_TOLERANCE:
        raise RuntimeError(f"{garment_id}: ONNX export is {error:.2g} m off the reference")
    return error


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("ids", nargs="*")
    parser.add_argument("--out", type=Path, default=None, help="npz models directory (models/explicit)")
    args = parser.parse_args(argv)
    for gid in args.ids or load_catalog():
        off = export_explicit(gid, args.out)
        print(f"{gid}: exported, {off * 1e3:.4f} mm max off the numpy reference")


if __name__ == "__main__":
    main()
