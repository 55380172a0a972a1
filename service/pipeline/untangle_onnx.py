"""The neural untangling operator O_theta (paper 3.2, eq. 7) served with onnxruntime; no torch.

One network serves up to ``N_SLOTS`` = 5 layers (body + 4 garments) with the default weights (body
fixed, garments 1) and the gap ``delta`` recorded in its config. Unused slots are padded as inactive
(``PAD_F``, ``PAD_H``). Written by ``python -m training.untangler`` into ``models/untangler/``:

- ``values.onnx``: inputs ``f_star``, ``h_star`` ``(B, 5) float32`` -> ``f (B, 5) float32``;
- ``jacobian.onnx``: the same plus ``jacobian (B, 5, 10) float32``, ``d f_k / d (f*, h*)`` with the
  f* columns first, computed explicitly inside the graph;
- ``jacobian_row.onnx``: inputs ``f_star``, ``h_star`` and ``row (1, 5) float32`` -> ``f`` and
  ``jacobian_row (B, 10) float32`` = ``row @ jacobian``, one reverse pass (a one-hot ``row`` gives
  one row of the Jacobian, all the fit needs, at about a third of ``jacobian.onnx``'s cost);
- ``untangler.json``: training config, gap, export tolerances and measured errors.

The network blends a garment in over ``|h*| < h_band`` (config), where the exact operator switches at
h* = 0; the body's h* is ignored and its f passes through unchanged. This module holds the export
contract (names, opset, tolerances): ``export/untangler.py`` writes to it, ``NeuralUntangler`` reads it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import numpy as np

from service.pipeline.untangle import settled
from service.process.onnx_session import run_blocks
from service.process.paths import models_dir

N_SLOTS = 5
PAD_F = 0.0
"""f* of an unused slot (any value works: the slot is inactive)."""
PAD_H = 1.0
"""h* of an unused slot: inactive."""
INPUT_NAMES = ("f_star", "h_star")
OUTPUT_NAMES = ("f", "jacobian")
BATCH_AXIS = "points"
OPSET = 17
VALUES_FILE = "values.onnx"
JACOBIAN_FILE = "jacobian.onnx"
ROW_FILE = "jacobian_row.onnx"
ROW_INPUT = "row"
ROW_OUTPUT_NAMES = ("f", "jacobian_row")
CONFIG_FILE = "untangler.json"
EXPORT_TOLERANCE = {"f": (2e-6, 0.0), "jacobian": (1e-4, 1e-4), "jacobian_row": (1e-4, 1e-4)}
"""(atol, rtol) of onnxruntime vs torch that an export accepts: f in m, the Jacobian dimensionless
(its h* columns reach ~1 / h_band inside the blend band, hence the relative part); a row of it as
the whole."""
NEAR_SURFACE = 0.05
"""|f*| (m) below which a field value counts as near the surface (docs/design.md section 7)."""
ERROR_BOUND_MM = 0.5
"""Mean |O_theta - reference| (mm) near the surface that the committed model must meet."""
SETTLED_SLACK = 0.002
"""m: how far inside the feasible set (``service.pipeline.untangle.settled``) a point must lie for
``NeuralUntangler.screened`` to answer it without the network: half the default gap."""


def default_directory() -> Path:
    return models_dir() / "untangler"


BATCH = 1024
"""Points per onnxruntime call: bounds the Jacobian graph's activations and keeps them in a core's cache, as
the fields' batches do (``service.pipeline.fields.BATCH``; one thread, per point: values 0.70 against
0.76 us in calls of 8,192, the Jacobian's row 1.68 against 1.83)."""


class NeuralUntangleOutput(NamedTuple):
    """f: ``(B, N) float64`` untangled fields. jacobian: ``(B, N, 2N) float64``, ``d f_k / d f*_j`` in
    columns ``j < N`` and ``d f_k / d h*_j`` in column ``N + j``; only row k, ``(B, 1, 2N)``, when
    called with ``row=k``; None when not asked for."""

    f: np.ndarray
    jacobian: np.ndarray | None


class NeuralUntangler:
    """onnxruntime sessions of the exported network; ``__call__`` pads to the 5 slots and back."""

    def __init__(self, directory: Path | None = None, threads: int = 2):
        from service.process.onnx_session import open_session

        directory = Path(directory or default_directory())
        self.config = json.loads((directory / CONFIG_FILE).read_text())
        self.delta = float(self.config["delta"])
        self.h_band = float(self.config["config"]["h_band"])
        self.threads = threads
        # One intra-op thread each: a call's batches run side by side (``run_blocks``).
        self._values, self._jacobian, self._row = (
            open_session(directory / name, 1) for name in (VALUES_FILE, JACOBIAN_FILE, ROW_FILE)
        )

    def __call__(self, f_star, h_star, jacobian: bool = True, row: int | None = None) -> NeuralUntangleOutput:
        """Untangle ``f_star``, ``h_star`` ``(B, N)``, N <= 5, layer 0 the body (see
        service.pipeline.untangle); ``row=k`` (0 <= k < N) computes only row k of the Jacobian, ~3x faster
        than all of it."""
        f_star, h_star = _checked(f_star, h_star, row)
        B, n = f_star.shape
        f_in = np.full((B, N_SLOTS), PAD_F, dtype=np.float32)
        h_in = np.full((B, N_SLOTS), PAD_H, dtype=np.float32)
        f_in[:, :n], h_in[:, :n] = f_star, h_star
        feeds = dict(zip(INPUT_NAMES, (f_in, h_in), strict=True))
        cols = np.r_[0:n, N_SLOTS : N_SLOTS + n]
        split = set(INPUT_NAMES)

        def run(session, names):
            return run_blocks(session, list(names), feeds, split, BATCH, self.threads)

        if not jacobian:
            (f,) = run(self._values, OUTPUT_NAMES[:1])
            return NeuralUntangleOutput(f[:, :n].astype(np.float64), None)
        if row is not None:
            feeds[ROW_INPUT] = np.eye(1, N_SLOTS, int(row), dtype=np.float32)
            f, jac = run(self._row, ROW_OUTPUT_NAMES)
            return NeuralUntangleOutput(f[:, :n].astype(np.float64), jac[:, None, cols].astype(np.float64))
        f, jac = run(self._jacobian, OUTPUT_NAMES)
        return NeuralUntangleOutput(f[:, :n].astype(np.float64), jac[:, :n][:, :, cols].astype(np.float64))

    def screened(self, f_star, h_star, jacobian: bool = True, row: int | None = None) -> NeuralUntangleOutput:
        """``__call__`` where untangling can move something; at the points ``settled`` (module
        ``service.pipeline.untangle``: the layers already ``delta + SETTLED_SLACK`` apart, none switching)
        f* itself and the identity's Jacobian, which the exact operator is there for every blend of
        the layers. The network's answer at those points is only its error: up to 3.7 mm at vertices
        near a garment's openings, where it blends h* (measured on the latency benchmark's outfits);
        and it runs on a third to two thirds fewer points."""
        f_star, h_star = _checked(f_star, h_star, row)
        B, n = f_star.shape
        busy = np.flatnonzero(~settled(f_star, h_star, self.delta, self.h_band, SETTLED_SLACK))
        f = f_star.astype(np.float64)
        jac = None
        if jacobian:
            rows = [row] if row is not None else list(range(n))
            jac = np.zeros((B, len(rows), 2 * n))
            jac[:, np.arange(len(rows)), rows] = 1.0
        if len(busy):
            out = self(f_star[busy], h_star[busy], jacobian, row)
            f[busy] = out.f
            if jacobian:
                jac[busy] = out.jacobian
        return NeuralUntangleOutput(f, jac)


def _checked(f_star, h_star, row) -> tuple[np.ndarray, np.ndarray]:
    f_star, h_star = np.asarray(f_star), np.asarray(h_star)
    if f_star.ndim != 2 or not 1 <= f_star.shape[1] <= N_SLOTS or h_star.shape != f_star.shape:
        raise ValueError(
            f"f_star and h_star must both be (B, N) with 1 <= N <= {N_SLOTS}, got {f_star.shape}"
            f" and {h_star.shape}"
        )
    n = f_star.shape[1]
    layer = isinstance(row, int | np.integer) and not isinstance(row, bool) and 0 <= row < n
    if row is not None and not layer:
        raise ValueError(f"row must be a layer in 0..{n - 1}, got {row!r}")
    return f_star, h_star
