"""Export the trained neural fields to ONNX: ``python -m export.fields [ids...]`` reads the finished
checkpoints of ``python -m training.fields`` (``build/fields/<id>.pt``) and writes ``models/fields/``.

The contract (names, points axis, opset, tolerances) lives in ``service.pipeline.fields``. Three graphs per
field: values (f, h; what the 30k-point speed target counts), values with both x-gradients, and values with
grad f alone. The export is a
contract plus a check: both files are run with onnxruntime on check points around the surface and the export
raises unless they match torch within ``EXPORT_TOLERANCE``.

``python -m export.fields --gradients-only [ids...]`` re-exports the gradient graphs alone: the weights are
read back from the committed values graphs (``load_exported``), the new graphs are checked against torch
and against the full gradient graph they replace, and ``fields.json`` records the new check. Then refresh
the manifest (``python -m export.manifest``).
"""

from __future__ import annotations

import argparse
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
from onnx import numpy_helper

from export.untangler import max_excess
from service.pipeline.fields import (
    CONFIG_FILE,
    EXPORT_TOLERANCE,
    F_GRADIENT_NAMES,
    GRADIENT_NAMES,
    INPUT_NAMES,
    OPSET,
    POINTS_AXIS,
    VALUE_NAMES,
    NeuralField,
    f_gradient_file,
    gradient_file,
    values_file,
)
from training.fields.net import FieldConfig, FieldNet


class _Values(torch.nn.Module):
    def __init__(self, net: FieldNet):
        super().__init__()
        self.net = net

    def forward(self, x, beta):
        return self.net(x, beta)


class _WithGradient(_Values):
    def forward(self, x, beta):
        return self.net.with_gradient(x, beta)


class _WithFGradient(_Values):
    def forward(self, x, beta):
        return self.net.with_gradient(x, beta, h_gradient=False)


def _gradient_graphs():
    """(graph kind as ``NeuralField`` takes it, file name, module, outputs) of the gradient graphs,
    looked up when called (a test swaps a module for a wrong one)."""
    return (
        (True, gradient_file, _WithGradient, GRADIENT_NAMES),
        ("f", f_gradient_file, _WithFGradient, F_GRADIENT_NAMES),
    )


def _export_graph(module: torch.nn.Module, path: Path, outputs: tuple[str, ...], x, beta) -> None:
    with warnings.catch_warnings():  # the TorchScript exporter is deliberate (no onnxscript)
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(
            module, (x, beta), str(path), dynamo=False, opset_version=OPSET,
            input_names=list(INPUT_NAMES), output_names=list(outputs),
            dynamic_axes={"x": {0: POINTS_AXIS}, **{o: {0: POINTS_AXIS} for o in outputs}},
        )  # fmt: skip
    onnx.checker.check_model(onnx.load(str(path)), full_check=True)


def _check(
    field: NeuralField, gradient, x: np.ndarray, beta: np.ndarray, reference: dict,
    against: str = "torch",
) -> dict:  # fmt: skip
    """Max abs difference per output of ``field`` (``gradient`` as ``NeuralField`` takes it) vs
    ``reference``; RuntimeError beyond tolerance."""
    check = {}
    values = field(x, beta[0], gradient=gradient)._asdict()
    names = {False: VALUE_NAMES, True: GRADIENT_NAMES, "f": F_GRADIENT_NAMES}[gradient]
    prefix = {False: "values", True: "grad", "f": "gradf"}[gradient]
    for output in names:
        ours = values[output].astype(np.float32)
        diff = float(np.abs(ours - reference[output]).max())
        check[f"{prefix}:{output}"] = diff
        if max_excess(ours, reference[output], EXPORT_TOLERANCE[output]) > 0:
            raise RuntimeError(
                f"{field.field_id} output {output!r} differs from {against} by {diff:.3g} beyond the "
                f"tolerance (atol, rtol) = {EXPORT_TOLERANCE[output]}"
            )
    return check


def _torch_reference(net: FieldNet, x: np.ndarray, beta: np.ndarray) -> dict:
    with torch.no_grad():
        out = net.with_gradient(torch.from_numpy(x), torch.from_numpy(beta))
    return dict(zip(GRADIENT_NAMES, (t.numpy() for t in out), strict=True))


def export_field(net: FieldNet, field_id: str, directory: Path, x: np.ndarray, beta: np.ndarray) -> dict:
    """Write ``<id>.onnx``, ``<id>.grad.onnx`` and ``<id>.gradf.onnx``; check them at ``x (P, 3)``,
    ``beta (1, 3)`` float32 against torch. Returns the max abs difference per output; raises
    RuntimeError beyond tolerance."""
    directory.mkdir(parents=True, exist_ok=True)
    net = net.float().eval()
    xt, bt = torch.from_numpy(x), torch.from_numpy(beta)
    reference = _torch_reference(net, x, beta)
    _export_graph(_Values(net), directory / values_file(field_id), VALUE_NAMES, xt[:5], bt)
    for _, name, module, outputs in _gradient_graphs():
        _export_graph(module(net), directory / name(field_id), outputs, xt[:5], bt)
    field = NeuralField(field_id, directory, threads=1)
    check = _check(field, False, x, beta, reference)
    for kind, *_ in _gradient_graphs():
        check |= _check(field, kind, x, beta, reference)
    return check


def load_exported(field_id: str, directory: Path) -> FieldNet:
    """The network of the committed values graph ``<id>.onnx`` (config from ``fields.json``).

    Named initializers map to parameters by name; the three the TorchScript exporter left unnamed
    (transposed matrices) by shape: first layer (3 + 2m, W), its beta part (3, W), frequencies (3, m),
    which are also regenerated from the seed and must agree."""
    config = FieldConfig(**json.loads((directory / CONFIG_FILE).read_text())["fields"][field_id]["config"])
    graph = onnx.load(str(directory / values_file(field_id))).graph
    arrays = {i.name: numpy_helper.to_array(i) for i in graph.initializer}
    net = FieldNet(config, arrays["net.centre"].copy(), 1.0 / float(arrays["net.inv_extent"]))
    unnamed = {a.shape: a for name, a in arrays.items() if not name.startswith("net.")}
    n_in, width = 3 + 2 * config.fourier, config.width
    if len(unnamed) != 3 or width == config.fourier:
        raise ValueError(f"{field_id}: cannot tell the unnamed initializers apart ({sorted(unnamed)})")
    state = net.state_dict()
    loaded = {k[len("net.") :]: v for k, v in arrays.items() if k.startswith("net.")}
    loaded |= {"first.weight": unnamed[(n_in, width)].T, "first_beta.weight": unnamed[(3, width)].T}
    if set(loaded) != set(state) - {"freqs"}:
        raise ValueError(f"{field_id}: parameters {sorted(set(state) ^ set(loaded))} do not match")
    if not np.array_equal(unnamed[(3, config.fourier)], state["freqs"].numpy().T):
        raise ValueError(f"{field_id}: frequencies differ from the ones seed {config.seed} gives")
    loaded = {k: torch.from_numpy(np.array(v, dtype=np.float32)) for k, v in loaded.items()}
    net.load_state_dict(state | loaded)
    return net.eval()


def reexport_gradient(field_id: str, directory: Path, x: np.ndarray, beta: np.ndarray) -> dict:
    """Rewrite ``<id>.grad.onnx`` and ``<id>.gradf.onnx`` from the weights of ``<id>.onnx``; check
    them at ``x (P, 3)``, ``beta (1, 3)`` float32 against torch and against the full gradient graph
    they replace (both within ``EXPORT_TOLERANCE``). Returns the checks against torch, as
    ``export_field``'s ``grad:`` and ``gradf:`` entries."""
    net = load_exported(field_id, directory)
    previous = NeuralField(field_id, directory, threads=1)(x, beta[0], gradient=True)._asdict()
    previous = {k: v.astype(np.float32) for k, v in previous.items()}
    reference = _torch_reference(net, x, beta)
    check = {}
    with tempfile.TemporaryDirectory() as tmp:
        for _, name, module, outputs in _gradient_graphs():
            _export_graph(module(net), Path(tmp) / name(field_id), outputs, torch.from_numpy(x[:5]),
                          torch.from_numpy(beta))  # fmt: skip
        os.symlink((directory / values_file(field_id)).resolve(), Path(tmp) / values_file(field_id))
        field = NeuralField(field_id, Path(tmp), threads=1)
        for kind, *_ in _gradient_graphs():
            check |= _check(field, kind, x, beta, reference)
            _check(field, kind, x, beta, previous, "the old graph")
        for _, name, *_ in _gradient_graphs():
            os.replace(Path(tmp) / name(field_id), directory / name(field_id))
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


def main(argv: list[str] | None = None) -> None:
    from service.pipeline.catalog import load_catalog
    from service.pipeline.fields import BODY, default_directory
    from training.fields.train import Surfaces, field_errors, finished_run, held_out, torch_predict

    parser = argparse.ArgumentParser(description="Export the trained neural fields to ONNX.")
    parser.add_argument("ids", nargs="*", help=f"garment ids or {BODY!r} (default: all)")
    parser.add_argument("--out", type=Path, default=None, help="default: models/fields")
    parser.add_argument("--gradients-only", action="store_true",
                        help="re-export only the gradient graphs, from the weights in --out")  # fmt: skip
    args = parser.parse_args(argv)
    directory = args.out or default_directory()
    for field_id in args.ids or [*load_catalog(), BODY]:
        surfaces = Surfaces(field_id)
        tests = held_out(surfaces)
        beta, samples = tests[0]  # the check points: around the surface, on a held-out shape
        x, beta = samples.x[:4096].astype(np.float32), beta[None].astype(np.float32)
        if not args.gradients_only:
            run = finished_run(surfaces, field_id)
            if run is None:
                raise SystemExit(f"export.fields: no finished checkpoint of {field_id} (training.fields)")
            errors = field_errors(torch_predict(run.net), tests)
            check = export_field(run.net, field_id, directory, x, beta)
            write_config(directory, {field_id: field_entry(run.net, check, errors, run.seconds)})
            print(
                f"{field_id}: held-out f {errors['f_mm']:.2f} mm, h {errors['h_mm']:.2f} mm; "
                f"export check {max(check.values()):.2g}"
            )
            continue
        check = reexport_gradient(field_id, directory, x, beta)
        entry = json.loads((directory / CONFIG_FILE).read_text())["fields"][field_id]
        checks = entry["export_check_max_abs_diff"] | check
        write_config(directory, {field_id: entry | {"export_check_max_abs_diff": checks}})
        print(f"{field_id}: gradient graph re-exported; check vs torch {max(check.values()):.2g}")


if __name__ == "__main__":
    main()
