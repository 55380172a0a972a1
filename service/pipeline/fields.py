"""Neural fields g(x, beta) = (f, h) of the garments and the body, served with onnxruntime; no torch.

Per field id (a garment id, or ``body``) ``python -m training.fields`` writes into ``models/fields/``:

- ``<id>.onnx``: inputs ``x (P, 3)``, ``beta (1, 3)`` float32 -> ``f (P,)``, ``h (P,)`` float32;
- ``<id>.grad.onnx``: the same plus ``grad_f (P, 3)``, ``grad_h (P, 3)``, the x-gradients computed
  in reverse mode inside the graph;
- ``<id>.gradf.onnx``: f, h and ``grad_f`` alone, one cotangent instead of two (~30 % less work):
  the fit asks for grad h only where the untangler can use it. A directory without it (a garment
  imported before it existed) is served by ``<id>.grad.onnx``, its grad h dropped;
- ``fields.json``: per id the training config, held-out errors and the export check.

x is in canonical space (metres, Anny's frame); f < 0 on the body side, h > 0 beyond the openings
(docs/design.md section 3). The body's h is not learned: it is always active, so ``FieldSet`` returns
h = -1 for it. This module holds the export contract (names, opset, tolerances): ``export/fields.py``
writes to it, ``NeuralField`` reads it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np

from service.process.onnx_session import open_session, run_blocks
from service.process.paths import models_dir

BODY = "body"
INPUT_NAMES = ("x", "beta")
VALUE_NAMES = ("f", "h")
GRADIENT_NAMES = ("f", "h", "grad_f", "grad_h")
F_GRADIENT_NAMES = ("f", "h", "grad_f")
POINTS_AXIS = "points"
OPSET = 17
CONFIG_FILE = "fields.json"
EXPORT_TOLERANCE = {"f": (2e-6, 1e-4), "h": (2e-6, 1e-4), "grad_f": (1e-4, 1e-3), "grad_h": (1e-4, 1e-3)}
"""(atol, rtol) of onnxruntime vs torch that an export accepts (values in m, gradients unitless)."""


def default_directory() -> Path:
    return models_dir() / "fields"


def values_file(field_id: str) -> str:
    return f"{field_id}.onnx"


def gradient_file(field_id: str) -> str:
    return f"{field_id}.grad.onnx"


def f_gradient_file(field_id: str) -> str:
    return f"{field_id}.gradf.onnx"


Gradient = bool | Literal["f"]
"""What a field call returns with its values: no gradient (False), both (True), or grad f alone
("f", grad_h then zeros)."""


class FieldValues(NamedTuple):
    """f, h ``(P,) float64``; grad_f, grad_h ``(P, 3) float64`` or None when not asked for."""

    f: np.ndarray
    h: np.ndarray
    grad_f: np.ndarray | None
    grad_h: np.ndarray | None


BATCH = 1024
"""Points per onnxruntime call of the values graph. A batch's activations (1,024 x 96 floats a layer,
0.4 MB) stay in a core's cache: per point, the T-shirt's values graph on one thread takes 0.47 us in
calls of 1,024 against 0.55 in calls of 8,192, its grad f graph 1.07 against 1.39 (4,096) and the full
gradient graph 1.47 against 1.84, most of that in the element-wise products of the slopes (a one-off
timing; ``benchmarks.latency``'s field line is the rerunnable measure). A point's answer does not
depend on its batch."""
GRADIENT_BATCH = 1024
"""Points per call of the gradient graphs (``BATCH``). They also bound the activations' memory: at 8,192
the full gradient graph's buffers outgrew what ``service.process.tuning`` keeps in the heap and every call
page-faulted ~28 MB in again."""


class NeuralField:
    """The two onnxruntime sessions of one field."""

    def __init__(self, field_id: str, directory: Path | None = None, threads: int = 2):
        directory = Path(directory or default_directory())
        self.field_id = field_id
        self.threads = threads
        # One intra-op thread per session: a call's batches run side by side on ``threads`` threads
        # instead (``service.process.onnx_session.run_blocks``).
        self._values = open_session(directory / values_file(field_id), 1)
        self._gradient = open_session(directory / gradient_file(field_id), 1)
        path = directory / f_gradient_file(field_id)
        self._f_gradient = open_session(path, 1) if path.is_file() else None

    def __call__(self, x: np.ndarray, beta: np.ndarray, gradient: Gradient = False) -> FieldValues:
        """Fields at ``x (P, 3)`` for one shape ``beta (3,)``; ``gradient`` as ``Gradient``."""
        x = np.ascontiguousarray(x, dtype=np.float32)
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"x must be (P, 3), got {x.shape}")
        if gradient not in (False, True, "f"):
            raise ValueError(f"gradient must be False, True or 'f', got {gradient!r}")
        beta = np.asarray(beta, dtype=np.float32).reshape(1, 3)
        if gradient == "f" and self._f_gradient is not None:
            out = self._run(self._f_gradient, F_GRADIENT_NAMES, GRADIENT_BATCH, x, beta)
            return FieldValues(*out, np.zeros_like(out[2]))
        if gradient == "f":
            return self(x, beta[0], True)._replace(grad_h=np.zeros((len(x), 3)))
        session, names = (self._gradient, GRADIENT_NAMES) if gradient else (self._values, VALUE_NAMES)
        # Bounded batches bound the activations' memory (a jacket's 10k vertices with gradients
        # would otherwise take ~100 MB at once).
        out = self._run(session, names, GRADIENT_BATCH if gradient else BATCH, x, beta)
        return FieldValues(*out) if gradient else FieldValues(out[0], out[1], None, None)

    def _run(self, session, names, batch: int, x: np.ndarray, beta: np.ndarray) -> list[np.ndarray]:
        inputs = dict(zip(INPUT_NAMES, (x, beta), strict=True))
        out = run_blocks(session, list(names), inputs, {INPUT_NAMES[0]}, batch, self.threads)
        return [o.astype(np.float64) for o in out]


class FieldSet:
    """Every field in a directory, by id; the body's h is the constant -1 (always active)."""

    def __init__(self, directory: Path | None = None, threads: int = 2):
        directory = Path(directory or default_directory())
        self.threads = threads
        self.config = json.loads((directory / CONFIG_FILE).read_text())
        self.fields = {fid: NeuralField(fid, directory, threads) for fid in self.config["fields"]}

    def add(self, directory: Path) -> list[str]:
        """Also serve the fields of ``directory`` (an imported garment's); returns their ids. An id
        already served is refused: an import never replaces a field."""
        config = json.loads((Path(directory) / CONFIG_FILE).read_text())
        taken = sorted(set(config["fields"]) & set(self.fields))
        if taken:
            raise ValueError(f"{directory}: fields {taken} are already served")
        self.config["fields"] |= config["fields"]
        self.fields |= {fid: NeuralField(fid, Path(directory), self.threads) for fid in config["fields"]}
        return list(config["fields"])

    def __call__(
        self, field_id: str, x: np.ndarray, beta: np.ndarray, gradient: Gradient = False
    ) -> FieldValues:
        out = self.fields[field_id](x, beta, gradient)
        if field_id != BODY:
            return out
        h = np.full_like(out.f, -1.0)
        return FieldValues(out.f, h, out.grad_f, None if out.grad_h is None else np.zeros_like(out.grad_f))
