"""Pipeline latency, one request at a time, cold (every body shape new), as the service runs it.

Run (a few minutes)::

    python -m benchmarks.latency [--bodies 8] [--threads 2]

For body + 1, 2 and 3 garments (tops stacked, a bottom under them), ``--bodies`` random shapes from the
supported box each: p50 / p95 of the total and the p50 of every stage (``report["seconds"]``; no quality
measures, as the service calls it; the garments' fits run side by side, so "fit" is their wall time and
fields / untangle / optimise are summed over the garments), then the field evaluation at 30,000 points
(values only, and with x-gradients) for the speed target of the issue. No cache: every shape is new.
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks.untangler import median_ms
from service.pipeline.outfit import OutfitModels, make_outfit
from training.drape.dataset import sample_betas

OUTFITS = (("tshirt",), ("tshirt", "jacket"), ("pants", "tshirt", "jacket"))
SEED = 21  # shapes used by no training and no other benchmark
STAGES = ("body", "explicit", "fit", "fields", "untangle", "optimise", "world", "repair")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--bodies", type=int, default=8)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args(argv)
    models = OutfitModels.load(threads=args.threads)
    betas = sample_betas(args.bodies, SEED)
    make_outfit(models, ["shorts"], betas[0], measure=False)  # warm-up: sessions, caches, allocator
    print(f"## Latency, one request at a time, {args.bodies} new body shapes per outfit (ms)")
    print(f"| outfit | p50 | p95 | {' | '.join(STAGES)} |")
    print("|---|---:|---:|" + "---:|" * len(STAGES))
    for ids in OUTFITS:
        reports = [make_outfit(models, list(ids), b, measure=False).report for b in betas]
        total = np.array([r["seconds"]["total"] for r in reports]) * 1e3
        stages = [np.median([r["seconds"].get(s, 0.0) for r in reports]) * 1e3 for s in STAGES]
        print(
            f"| body + {' + '.join(ids)} | {np.median(total):.0f} | {np.percentile(total, 95):.0f} | "
            + " | ".join(f"{v:.0f}" for v in stages)
            + " |"
        )
    rng = np.random.default_rng(0)
    x = models.explicit["tshirt"].canonical(betas[0])
    points = x[rng.integers(0, len(x), 30_000)] + rng.normal(scale=0.01, size=(30_000, 3))
    values = median_ms(lambda: models.fields("tshirt", points, betas[0]), 7)
    grads = median_ms(lambda: models.fields("tshirt", points, betas[0], True), 7)
    print(f"\nfield at 30,000 points: values {values:.1f} ms, values with x-gradients {grads:.1f} ms")


if __name__ == "__main__":
    main()
