"""Neural fields: the paper's Table 1 ablation, every field's held-out error, and evaluation speed.

Run (about 25 minutes the first time: it trains the four ablation networks, resumable, under
``build/fields/``; a minute afterwards)::

    python -m benchmarks.fields [--ablation tshirt,pants] [--threads 2]

- Errors: mean |f - f_GT| and |h - h_GT| in mm at points within 1 cm of the surface (uniform normal
  offsets) on 16 held-out body shapes never used in training; ground truth as in training
  (``training.fields.samples``). The committed models are evaluated with onnxruntime.
- Ablation: the full model against the same network trained without Fourier features (x fed alone)
  and without the gradient losses (lambda = 0), everything else equal (torch, float32).
- Speed: median of 7 onnxruntime calls at 30,000 points, values only and values with x-gradients.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace

import numpy as np
import torch

from benchmarks.untangler import median_ms
from service.pipeline.fields import FieldSet, default_directory
from training.fields.net import FieldConfig
from training.fields.train import (
    Surfaces,
    field_errors,
    held_out,
    load_trained,
    torch_predict,
    train_field,
)

PAPER = {"tshirt": (1.1, 0.8, 2.0, 1.0, 5.3, 0.9), "dress": (1.3, 2.0, 1.6, 2.0, 6.6, 1.9)}
VARIANTS = {"no_fourier": {"fourier": 0}, "no_gradient": {"grad_weight": 0.0}}


def ablation_net(surfaces: Surfaces, base: FieldConfig, variant: str):
    name = f"{surfaces.field_id}-{variant}"
    net = load_trained(surfaces, name)
    if net is None:
        net = train_field(surfaces, replace(base, **VARIANTS[variant]), name=name).net
    return net


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--ablation", default="tshirt,pants")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    fields = FieldSet(threads=args.threads)
    meta = json.loads((default_directory() / "fields.json").read_text())["fields"]

    print("## Held-out error of every committed field (mm, within 1 cm of the surface; onnxruntime)")
    print("| field | f | h | width x depth | Fourier freqs | train min | 30k values ms | 30k with grads ms |")
    print("|---|---:|---:|---|---:|---:|---:|---:|")
    rng = np.random.default_rng(0)
    x30 = rng.normal(scale=0.2, size=(30000, 3)).astype(np.float32)
    full = {}
    for fid in fields.fields:
        surfaces = Surfaces(fid)
        tests = held_out(surfaces)
        err = field_errors(lambda x, b, fid=fid: fields(fid, x, b[0])[:2], tests)
        full[fid] = err
        beta = tests[0][0]
        t_val = median_ms(lambda fid=fid, beta=beta: fields(fid, x30, beta), 7)
        t_grad = median_ms(lambda fid=fid, beta=beta: fields(fid, x30, beta, gradient=True), 7)
        c = meta[fid]["config"]
        h = f"{err['h_mm']:.2f}" if fid != "body" else "-"
        print(
            f"| {fid} | {err['f_mm']:.2f} | {h} | {c['width']} x {c['depth']} | {c['fourier']} "
            f"| {meta[fid]['train_seconds'] / 60:.1f} | {t_val:.1f} | {t_grad:.1f} |"
        )

    print("\n## Ablation like the paper's Table 1 (mm, held-out shapes, within 1 cm of the surface)")
    print("| garment | full f | full h | no Fourier f | no Fourier h | no grad. sup. f | no grad. sup. h |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for gid in filter(None, args.ablation.split(",")):
        surfaces = Surfaces(gid)
        tests = held_out(surfaces)
        base = FieldConfig(**meta[gid]["config"])
        row = [full[gid]["f_mm"], full[gid]["h_mm"]]
        for variant in VARIANTS:
            err = field_errors(torch_predict(ablation_net(surfaces, base, variant)), tests)
            row += [err["f_mm"], err["h_mm"]]
        print(f"| {gid} (ours) | " + " | ".join(f"{v:.2f}" for v in row) + " |")
    for name, row in PAPER.items():
        print(f"| {name} (paper) | " + " | ".join(f"{v:.1f}" for v in row) + " |")


if __name__ == "__main__":
    main()
