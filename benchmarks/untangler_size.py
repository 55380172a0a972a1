"""Accuracy against cost of the neural untangling operator at different widths.

Run (about a minute once the operators are exported)::

    python -m training.untangler --hidden 64 --checkpoint build/untangler64.ckpt   # ~7 min, one core
    python -m export.untangler --checkpoint build/untangler64.ckpt --out build/untangler64
    python -m benchmarks.untangler_size models/untangler build/untangler64

For each exported operator directory: its width, its error against the exact operator on fresh samples
(``benchmarks.untangler.error_rows``: near-surface mean per distribution) and the time of the two calls
a fit makes, values at every vertex and values with one Jacobian row at the optimised ones, on 10,000
layered-outfit points of 5 layers with 2 onnxruntime threads (median of ``--repeats``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks.untangler import error_rows, median_ms
from service.pipeline.untangle_onnx import CONFIG_FILE, NeuralUntangler
from training.untangler_data import sample_layered


def row(directory: Path, threads: int, repeats: int) -> str:
    neural = NeuralUntangler(directory, threads)
    config = json.loads((directory / CONFIG_FILE).read_text())["config"]
    f, h = sample_layered(np.random.default_rng(7), 10_000)
    values = median_ms(lambda: neural(f, h, jacobian=False), repeats)
    jacobian_row = median_ms(lambda: neural(f, h, row=2), repeats)
    errors = {name: near for name, _, near, _ in error_rows(neural)}
    cells = [f"{config['hidden']} x {config['depth']}", *(f"{errors[k]:.3f}" for k in sorted(errors))]
    return "| " + " | ".join([*cells, f"{values:.1f}", f"{jacobian_row:.1f}"]) + " |"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("directories", nargs="+", type=Path)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args(argv)
    print("## Neural untangler: near-surface error (mm) against cost (ms at 10,000 points)")
    print("| width x depth | layered | near_zero | paper | values | values + Jacobian row |")
    print("|---|---:|---:|---:|---:|---:|")
    for directory in args.directories:
        print(row(directory, args.threads, args.repeats))


if __name__ == "__main__":
    main()
