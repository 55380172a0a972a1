"""Export the trained neural untangling operator to ONNX: ``python -m export.untangler`` reads the
finished checkpoint of ``python -m training.untangler`` and writes ``models/untangler/``.

The contract (input/output names, batch axis, opset, tolerances) lives in ``service.pipeline.untangle_onnx``.
Three graphs: ``values.onnx`` (f only, what the 30k-point speed target counts), ``jacobian.onnx``
(f and its Jacobian w.r.t. f* and h*, computed explicitly inside the graph) and ``jacobian_row.onnx``
(f and one weighted row of it, what the fit uses). The export is a contract plus a check: every file is
run with onnxruntime on a check batch (every sampler, points inside the h* blend band, padded slots)
and the export raises unless it matches torch within ``EXPORT_TOLERANCE``, the row graph for each of
the 5 one-hot rows, also against the rows of ``jacobian.onnx``.

``python -m export.untangler --row-only`` re-exports the row graph alone: the weights are read back
from the committed ``values.onnx`` (``load_exported``), the new graph is checked against torch and
against the rows of the committed ``jacobian.onnx``, and ``untangler.json`` records the check. Then
refresh the manifest (``python -m export.manifest``).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import warnings
from dataclasses import asdict
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import torch
from onnx import numpy_helper

from service.pipeline.untangle_onnx import (
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
    ROW_FILE,
    ROW_INPUT,
    ROW_OUTPUT_NAMES,
    VALUES_FILE,
    default_directory,
)
from training.untangler import UntanglerConfig, UntanglerNet, evaluate, load_trained
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


class _WithJacobianRow(_Values):
    def forward(self, f_star, h_star, row):
        return self.net.with_jacobian_row(f_star, h_star, row)


ONE_HOT_ROWS = np.eye(N_SLOTS, dtype=np.float32)[:, None]  # (5, 1, 5): the rows the check asks for


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


def _export_graph(module: torch.nn.Module, path: Path, inputs: tuple, names: tuple, outputs: tuple) -> None:
    with warnings.catch_warnings():  # the TorchScript exporter is deliberate (no onnxscript)
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", torch.jit.TracerWarning)  # constants from numpy, meant as such
        torch.onnx.export(
            module, inputs, str(path), dynamo=False, opset_version=OPSET,
            input_names=list(names), output_names=list(outputs),
            dynamic_axes={a: {0: BATCH_AXIS} for a in (*INPUT_NAMES, *outputs)},
        )  # fmt: skip
    onnx.checker.check_model(onnx.load(str(path)), full_check=True)


def _session(path: Path) -> ort.InferenceSession:
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def _compare(ours: np.ndarray, reference: np.ndarray, key: str, output: str, against: str) -> float:
    """Max abs difference; RuntimeError beyond ``EXPORT_TOLERANCE[output]``."""
    diff = float(np.abs(ours - reference).max())
    if max_excess(ours, reference, EXPORT_TOLERANCE[output]) > 0:
        raise RuntimeError(
            f"{key} differs from {against} by {diff:.3g} beyond the tolerance (atol, rtol) = "
            f"{EXPORT_TOLERANCE[output]}"
        )
    return diff


def run_rows(path: Path, f: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The row graph at ``path`` for each one-hot row: (f ``(5, B, 5)``, rows ``(5, B, 10)``)."""
    session = _session(path)
    runs = [
        session.run(list(ROW_OUTPUT_NAMES), {"f_star": f, "h_star": h, ROW_INPUT: r}) for r in ONE_HOT_ROWS
    ]
    return np.stack([r[0] for r in runs]), np.stack([r[1] for r in runs])


def torch_rows(net: UntanglerNet, f: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``with_jacobian_row`` for each one-hot row, as ``run_rows``."""
    ft, ht = torch.from_numpy(f), torch.from_numpy(h)
    with torch.no_grad():
        runs = [net.with_jacobian_row(ft, ht, torch.from_numpy(r)) for r in ONE_HOT_ROWS]
    return np.stack([r[0].numpy() for r in runs]), np.stack([r[1].numpy() for r in runs])


def check_row_graph(
    path: Path, net: UntanglerNet, jacobian: np.ndarray, f: np.ndarray, h: np.ndarray
) -> dict:
    """Check the row graph at ``path`` on the check batch ``f``, ``h`` ``(B, 5)`` against torch and
    against the rows of ``jacobian (B, 5, 10)`` (a ``jacobian.onnx`` output); raises RuntimeError
    beyond tolerance. Returns the max abs differences."""
    values, rows = run_rows(path, f, h)
    reference_f, reference_rows = torch_rows(net, f, h)
    against_full = np.moveaxis(jacobian, 1, 0)  # (5, B, 10)
    key = f"{path.name}:{ROW_OUTPUT_NAMES[1]}"
    return {
        f"{path.name}:f": _compare(values, reference_f, f"{path.name}:f", "f", "torch"),
        key: _compare(rows, reference_rows, key, ROW_OUTPUT_NAMES[1], "torch"),
        f"{key} vs {JACOBIAN_FILE}": _compare(rows, against_full, key, ROW_OUTPUT_NAMES[1], JACOBIAN_FILE),
    }


def export(net: UntanglerNet, directory: Path, metrics: dict | None = None) -> dict:
    """Write the three graphs and the config json to ``directory``; returns the export check
    (max abs difference onnxruntime vs torch per output). Raises RuntimeError beyond tolerance."""
    directory.mkdir(parents=True, exist_ok=True)
    net = net.float().eval()
    f, h = check_inputs(net)
    ft, ht = torch.from_numpy(f), torch.from_numpy(h)
    with torch.no_grad():
        reference = dict(zip(OUTPUT_NAMES, (t.numpy() for t in net.with_jacobian(ft, ht)), strict=True))
    check = {}
    for module, name, outputs in (
        (_Values(net), VALUES_FILE, OUTPUT_NAMES[:1]),
        (_WithJacobian(net), JACOBIAN_FILE, OUTPUT_NAMES),
    ):
        path = directory / name
        _export_graph(module, path, (ft[:2], ht[:2]), INPUT_NAMES, outputs)
        results = _session(path).run(list(outputs), dict(zip(INPUT_NAMES, (f, h), strict=True)))
        for output, value in zip(outputs, results, strict=True):
            key = f"{name}:{output}"
            check[key] = _compare(value, reference[output], f"{path} output {output!r}", output, "torch")
    jacobian = _session(directory / JACOBIAN_FILE).run([OUTPUT_NAMES[1]], {"f_star": f, "h_star": h})[0]
    row_inputs = (ft[:2], ht[:2], torch.from_numpy(ONE_HOT_ROWS[1]))
    _export_graph(
        _WithJacobianRow(net), directory / ROW_FILE, row_inputs, (*INPUT_NAMES, ROW_INPUT), ROW_OUTPUT_NAMES
    )
    check |= check_row_graph(directory / ROW_FILE, net, jacobian, f, h)
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


def load_exported(directory: Path) -> UntanglerNet:
    """The network of the committed ``values.onnx`` (config from ``untangler.json``).

    Named initializers map to parameters by name (every parameter, nothing else); the one the
    TorchScript exporter left unnamed is the pair-difference matrix ``diff.T (5, 10)``, a buffer
    built from the config, which must agree. The weights of ``jacobian.onnx`` must be the same."""
    config = json.loads((directory / CONFIG_FILE).read_text())["config"]
    net = UntanglerNet(UntanglerConfig(**config | {"mixture": tuple(config["mixture"])}))

    def initializers(name: str) -> dict[str, np.ndarray]:
        graph = onnx.load(str(directory / name)).graph
        return {i.name: numpy_helper.to_array(i) for i in graph.initializer}

    arrays = initializers(VALUES_FILE)
    loaded = {k[len("net.") :]: v for k, v in arrays.items() if k.startswith("net.")}
    parameters = dict(net.named_parameters())
    if set(loaded) != set(parameters):
        raise ValueError(f"{VALUES_FILE}: parameters {sorted(set(parameters) ^ set(loaded))} do not match")
    for name, value in loaded.items():
        if value.shape != tuple(parameters[name].shape):
            raise ValueError(
                f"{VALUES_FILE}: {name} is {value.shape}, the config gives {parameters[name].shape}"
            )
    unnamed = [a for k, a in arrays.items() if not k.startswith("net.")]
    if len(unnamed) != 1 or not np.array_equal(unnamed[0], net.diff.numpy().T):
        raise ValueError(f"{VALUES_FILE}: the unnamed initializers are not the config's diff.T")
    full = initializers(JACOBIAN_FILE)
    if any(not np.array_equal(full.get(f"net.{k}"), v) for k, v in loaded.items()):
        raise ValueError(f"{JACOBIAN_FILE} holds other weights than {VALUES_FILE}")
    with torch.no_grad():
        for name, value in loaded.items():
            parameters[name].copy_(torch.from_numpy(np.array(value, dtype=np.float32)))
    return net.float().eval()


def reexport_row(directory: Path) -> dict:
    """Write ``jacobian_row.onnx`` from the weights of the committed ``values.onnx``; check it on the
    check batch against torch and against the rows of the committed ``jacobian.onnx`` (and the rebuilt
    network against both committed graphs), all within ``EXPORT_TOLERANCE``. Returns the check."""
    net = load_exported(directory)
    f, h = check_inputs(net)
    feeds = {"f_star": f, "h_star": h}
    values = _session(directory / VALUES_FILE).run([OUTPUT_NAMES[0]], feeds)[0]
    full_f, jacobian = _session(directory / JACOBIAN_FILE).run(list(OUTPUT_NAMES), feeds)
    with torch.no_grad():
        ours = [t.numpy() for t in net.with_jacobian(torch.from_numpy(f), torch.from_numpy(h))]
    _compare(ours[0], values, "the rebuilt network's f", "f", VALUES_FILE)
    _compare(ours[0], full_f, "the rebuilt network's f", "f", JACOBIAN_FILE)
    _compare(ours[1], jacobian, "the rebuilt network's jacobian", "jacobian", JACOBIAN_FILE)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / ROW_FILE
        row_inputs = (torch.from_numpy(f[:2]), torch.from_numpy(h[:2]), torch.from_numpy(ONE_HOT_ROWS[1]))
        _export_graph(_WithJacobianRow(net), path, row_inputs, (*INPUT_NAMES, ROW_INPUT), ROW_OUTPUT_NAMES)
        check = check_row_graph(path, net, jacobian, f, h)
        os.replace(path, directory / ROW_FILE)
    return check


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description="Export the trained untangling operator to ONNX.")
    parser.add_argument("--checkpoint", type=Path, default=Path("build/untangler.ckpt"),
                        help="a finished run of python -m training.untangler")  # fmt: skip
    parser.add_argument("--out", type=Path, default=None, help="default: models/untangler")
    parser.add_argument("--row-only", action="store_true",
                        help="re-export only jacobian_row.onnx from the weights in --out")  # fmt: skip
    args = parser.parse_args(argv)
    directory = args.out or default_directory()
    if not args.row_only:
        try:
            result = load_trained(args.checkpoint)
        except ValueError as e:
            raise SystemExit(f"export.untangler: {e}") from None
        meta = {
            "evaluation": evaluate(result.net),
            "train_seconds": round(result.seconds, 1),
            "torch_threads": result.torch_threads,
        }
        check = export(result.net, directory, metrics=meta)
        print(json.dumps(meta["evaluation"], indent=2))
        print(f"wrote {directory}; export check (max abs difference onnxruntime vs torch): {check}")
        return
    check = reexport_row(directory)
    meta = json.loads((directory / CONFIG_FILE).read_text())
    meta["export_check_max_abs_diff"] = {
        k: v for k, v in meta["export_check_max_abs_diff"].items() if not k.startswith(ROW_FILE)
    } | check
    (directory / CONFIG_FILE).write_text(json.dumps(meta, indent=2) + "\n")
    print(f"{directory / ROW_FILE} re-exported; check: {json.dumps(check)}")


if __name__ == "__main__":
    main()
