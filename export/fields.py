"""Export a trained neural field to ONNX (called by ``python -m training.fields``).

The contract (names, points axis, opset, tolerances) lives in ``service.fields``. Two graphs per field:
values (f, h; what the 30k-point speed target counts) and values with x-gradients. The export is a
contract plus a check: both files are run with onnxruntime on check points around the surface and the
export raises unless they match torch within ``EXPORT_TOLERANCE``.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import tempfile
import warnings
from dataclasses import asdict
from pathlib import Path

import numpy as np
import onnx
import torch

from export.untangler import max_excess
from service.fields import (
    CONFIG_FILE,
    EXPORT_TOLERANCE,
    GRADIENT_NAMES,
    INPUT_NAMES,
    OPSET,
    POINTS_AXIS,
    VALUE_NAMES,
    NeuralField,
    gradient_file,
    values_file,
)
from training.fields.net import FieldNet


class _Values(torch.nn.Module):
    def __init__(self, net: FieldNet):
        super().__init__()
        self.net = net

    def forward(self, x, beta):
        return self.net(x, beta)


class _WithGradient(_Values):
    def forward(self, x, beta):
        return self.net.with_gradient(x, beta)


def export_field(net: FieldNet, field_id: str, directory: Path, x: np.ndarray, beta: np.ndarray) -> dict:
    """Write ``<id>.onnx`` and ``<id>.grad.onnx``; check them at ``x (P, 3)``, ``beta (1, 3)`` float32
    against torch. Returns the max abs difference per output; raises RuntimeError beyond tolerance."""
    directory.mkdir(parents=True, exist_ok=True)
    net = net.float().eval()
    xt, bt = torch.from_numpy(x), torch.from_numpy(beta)
    with torch.no_grad():
        reference = dict(zip(GRADIENT_NAMES, (t.numpy() for t in net.with_gradient(xt, bt)), strict=True))
    for module, name, outputs in (
        (_Values(net), values_file(field_id), VALUE_NAMES),
        (_WithGradient(net), gradient_file(field_id), GRADIENT_NAMES),
    ):
        path = directory / name
        with warnings.catch_warnings():  # the TorchScript exporter is deliberate (no onnxscript)
            warnings.simplefilter("ignore", DeprecationWarning)
            torch.onnx.export(
                module, (xt[:5], bt), str(path), dynamo=False, opset_version=OPSET,
                input_names=list(INPUT_NAMES), output_names=list(outputs),
                dynamic_axes={"x": {0: POINTS_AXIS}, **{o: {0: POINTS_AXIS} for o in outputs}},
            )  # fmt: skip
        onnx.checker.check_model(onnx.load(str(path)), full_check=True)
    field = NeuralField(field_id, directory, threads=1)
    check = {}
    for gradient, outputs in ((False, VALUE_NAMES), (True, GRADIENT_NAMES)):
        values = field(x, beta[0], gradient=gradient)._asdict()
        for output in outputs:
            ours = values[output].astype(np.float32)
            diff = float(np.abs(ours - reference[output]).max())
            check[f"{'grad' if gradient else 'values'}:{output}"] = diff
            if max_excess(ours, reference[output], EXPORT_TOLERANCE[output]) > 0:
                raise RuntimeError(
                    f"{field_id} output {output!r} differs from torch by {diff:.3g} beyond the tolerance "
                    f"(atol, rtol) = {EXPORT_TOLERANCE[output]}"
                )
    return check


def write_config(directory: Path, entries: dict[str, dict]) -> Path:
    """Merge ``entries`` (field id -> metadata) into ``fields.json``, keeping other fields' entries."""
    path = directory / CONFIG_FILE
    directory.mkdir(parents=True, exist_ok=True)
    # Fields train in parallel processes: read-modify-write under an exclusive lock.
    key = hashlib.sha1(str(directory.resolve()).encode()).hexdigest()[:12]
    lock_path = Path(tempfile.gettempdir()) / f"ulnef-fields-{key}.lock"
    with open(lock_path, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        meta = json.loads(path.read_text()) if path.exists() else {"opset": OPSET, "fields": {}}
        meta["fields"].update(entries)
        meta["fields"] = dict(sorted(meta["fields"].items()))
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(meta, indent=2) + "\n")
        os.replace(tmp, path)
    return path


def field_entry(net: FieldNet, check: dict, errors: dict, seconds: float) -> dict:
    return {
        "config": asdict(net.config),
        "export_check_max_abs_diff": check,
        "held_out": errors,
        "train_seconds": round(seconds, 1),
    }
