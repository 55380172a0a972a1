"""Random garment orders: which stacks the service can untangle, and what the report says of the rest.

Run (a minute or two)::

    python -m benchmarks.orders [--outfits 24] [--seed 7]

``--outfits`` outfits of 1-4 catalog garments in random order (many of them orders cloth cannot take:
shorts over a skirt, a T-shirt over a jacket) on held-out body shapes (a Sobol seed no training used),
one request at a time as the service runs them (no quality measures). Per outfit: the report's
``collision_free`` and ``crossing_pairs`` after the repair, and the time.
"""

from __future__ import annotations

import argparse

import numpy as np

from service.pipeline.outfit import OutfitModels, make_outfit
from training.drape.dataset import sample_betas

BODY_SEED = 99


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--outfits", type=int, default=24)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args(argv)
    models = OutfitModels.load()
    rng = np.random.default_rng(args.seed)
    catalog = sorted(models.catalog)
    betas = sample_betas(args.outfits, BODY_SEED)
    print(f"## {args.outfits} random outfits (inner to outer) on held-out bodies")
    print("| outfit | body | collision free | crossing pairs | ms |")
    print("|---|---|---|---:|---:|")
    clean = 0
    for beta in betas:
        ids = [str(g) for g in rng.choice(catalog, size=rng.integers(1, 5), replace=False)]
        r = make_outfit(models, ids, beta, measure=False).report
        clean += r["collision_free"]
        body = ", ".join(f"{v:.2f}" for v in beta)
        print(f"| {' < '.join(ids)} | {body} | {'yes' if r['collision_free'] else 'no'} "
              f"| {r['crossing_pairs']} | {1e3 * r['seconds']['total']:.0f} |")  # fmt: skip
    print(f"\ncollision free: {clean} of {args.outfits}")


if __name__ == "__main__":
    main()
