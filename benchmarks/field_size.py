"""Accuracy against cost of the neural field's size: what a smaller network would save and lose.

Run (about 4 minutes per size on 2 cores; resumable, checkpoints in ``build/fields/``)::

    python -m benchmarks.field_size [--field tshirt] [--sizes 48x3,64x3,96x3] [--steps 3000]

Trains the field of ``--field`` at each width x depth (everything else as ``FieldConfig``: the
committed fields are 96 x 3), exports it to ONNX under ``build/field_size/``, and prints per size:
the held-out errors (mean |f - f_GT|, |h - h_GT| within 1 cm of the surface on 8 held-out shapes,
mm), and the onnxruntime time at 30,000 points near the garment, values and values with x-gradients
(2 threads, median of 7) — the two calls a request makes per layer and vertex.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.untangler import median_ms
from export.fields import export_field
from service.pipeline.fields import NeuralField
from training.fields.net import FieldConfig, fourier_sigma
from training.fields.train import Surfaces, field_errors, held_out, torch_predict, train_field

OUT = Path(__file__).resolve().parents[1] / "build" / "field_size"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--field", default="tshirt")
    parser.add_argument("--sizes", default="48x3,64x3,96x3", help="width x depth, comma-separated")
    parser.add_argument("--steps", type=int, default=FieldConfig.steps)
    args = parser.parse_args(argv)
    surfaces = Surfaces(args.field)
    sigma = fourier_sigma(surfaces.box()[1])
    tests = held_out(surfaces)
    beta, samples = tests[0]
    check_x, check_beta = samples.x[:4096].astype(np.float32), beta[None].astype(np.float32)
    rng = np.random.default_rng(0)
    near = np.concatenate([s.x for _, s in tests])
    points = near[rng.integers(0, len(near), 30_000)].astype(np.float64)
    rows = []
    for size in args.sizes.split(","):
        width, depth = (int(v) for v in size.split("x"))
        config = replace(FieldConfig(), steps=args.steps, sigma=sigma, width=width, depth=depth)
        name = f"size/{args.field}-w{width}-d{depth}-s{args.steps}"
        result = train_field(surfaces, config, name=name, log=lambda *_: None)
        errors = field_errors(torch_predict(result.net), tests)
        directory = OUT / f"{args.field}-w{width}-d{depth}-s{args.steps}"
        export_field(result.net, args.field, directory, check_x, check_beta)
        field = NeuralField(args.field, directory, threads=2)
        values = median_ms(lambda f=field: f(points, beta), 7)
        grads = median_ms(lambda f=field: f(points, beta, True), 7)
        weights = sum(p.numel() for p in result.net.parameters())
        rows.append((width, depth, weights, errors["f_mm"], errors["h_mm"], values, grads, result.seconds))
    print(f"## Field size against accuracy and cost: {args.field}, {args.steps} steps (2 threads)")
    print("| width x depth | weights | held-out f mm | held-out h mm | values ms at 30k "
          "| with gradients ms at 30k | training min |")  # fmt: skip
    print("|---|---:|---:|---:|---:|---:|---:|")
    for width, depth, weights, f_mm, h_mm, values, grads, seconds in rows:
        print(f"| {width} x {depth} | {weights:,} | {f_mm:.2f} | {h_mm:.2f} | {values:.1f} | {grads:.1f} "
              f"| {seconds / 60:.1f} |")  # fmt: skip


if __name__ == "__main__":
    main()
