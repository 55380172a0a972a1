"""Export the neural untangling operator to ONNX (called by ``python -m training.untangler``).

The contract (input/output names, batch axis, opset, tolerances) lives in ``service.untangle_onnx``.
Two graphs: ``values.onnx`` (f only, what the 30k-point speed target counts) and ``jacobian.onnx``
(f and its Jacobian w.r.t. f* and h*, computed explicitly inside the graph). The export is a contract
plus a check: both files are run with onnxruntime on a check batch (every sampler, points inside the h*
blend band, padded slots) and the export raises unless they match torch within ``EXPORT_TOLERANCE``.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import asdict
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import torch

from service.untangle_onnx import (
    BATCH_AXIS,
    CONFIG_FILE,
    EXPORT_TOLERANCE,
    INPUT_NAMES,
    JACOBIAN_FILE,
    N_SLOTS,
    OPSET,
    OUTPUT_NAMES,
    PAD_F,
    PAD_H,
    VALUES_FILE,
)
from training.untangler import UntanglerNet
from training.untangler_data import sample_batch

CHECK_POINTS = 4096
CHECK_SEED = 7


class _Values(torch.nn.Module):
    def __init__(self, net: UntanglerNet):
        super().__init__()
        self.net = net

    def forward(self, f_star, h_star):
        return self.net(f_star, h_star)


class _WithJacobian(_Values):
    def forward(self, f_star, h_star):
        return self.net.with_jacobian(f_star, h_star)


def check_inputs(net: UntanglerNet) -> tuple[np.ndarray, np.ndarray]:
    """``(f*, h*)`` ``(CHECK_POINTS, 5) float32`` from the training mixture, a quarter in the blend band."""
    rng = np.random.default_rng(CHECK_SEED)
    config = net.config
    f, h, _ = sample_batch(rng, CHECK_POINTS, config.mixture, config.h_band, config.padded)
    band = rng.random(h.shape) < 0.25
    band[:, 0] = False
    h[band] = rng.uniform(-1.5, 1.5, band.sum()) * net.config.h_band
    return f.astype(np.float32), h.astype(np.float32)


def max_excess(ours: np.ndarray, theirs: np.ndarray, tolerance: tuple[float, float]) -> float:
    """max(|ours - theirs| - (atol + rtol |theirs|)): <= 0 when within tolerance."""
    atol, rtol = tolerance
    return float(np.max(np.abs(ours - theirs) - (atol + rtol * np.abs(theirs))))


def export(net: UntanglerNet, directory: Path, metrics: dict | None = None) -> dict:
    """Write the two graphs and the config json to ``directory``; returns the export check
    (max abs difference onnxruntime vs torch per output). Raises RuntimeError beyond tolerance."""
    directory.mkdir(parents=True, exist_ok=True)
    net = net.float().eval()
    f, h = check_inputs(net)
    ft, ht = torch.from_numpy(f), torch.from_numpy(h)
    with torch.no_grad():
        reference = dict(zip(OUTPUT_NAMES, (t.numpy() for t in net.with_jacobian(ft, ht)), strict=True))
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    check = {}
    for module, name, outputs in (
        (_Values(net), VALUES_FILE, OUTPUT_NAMES[:1]),
        (_WithJacobian(net), JACOBIAN_FILE, OUTPUT_NAMES),
    ):
        path = directory / name
        with warnings.catch_warnings():  # the TorchScript exporter is deliberate (no onnxscript)
            warnings.simplefilter("ignore", DeprecationWarning)
            torch.onnx.export(
                module, (ft[:2], ht[:2]), str(path), dynamo=False, opset_version=OPSET,
                input_names=list(INPUT_NAMES), output_names=list(outputs),
                dynamic_axes={a: {0: BATCH_AXIS} for a in (*INPUT_NAMES, *outputs)},
            )  # fmt: skip
        onnx.checker.check_model(onnx.load(str(path)), full_check=True)
        session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        results = session.run(list(outputs), dict(zip(INPUT_NAMES, (f, h), strict=True)))
        for output, value in zip(outputs, results, strict=True):
            excess = max_excess(value, reference[output], EXPORT_TOLERANCE[output])
            diff = float(np.abs(value - reference[output]).max())
            check[f"{name}:{output}"] = diff
            if excess > 0:
                raise RuntimeError(
                    f"{path} output {output!r} differs from torch by {diff:.3g} beyond the tolerance "
                    f"(atol, rtol) = {EXPORT_TOLERANCE[output]}"
                )
    meta = {
        "config": asdict(net.config),
        "delta": net.config.delta,
        "n_slots": N_SLOTS,
        "pad": {"f": PAD_F, "h": PAD_H},
        "opset": OPSET,
        "export_check_max_abs_diff": check,
        **(metrics or {}),
    }
    (directory / CONFIG_FILE).write_text(json.dumps(meta, indent=2) + "\n")
    return check
