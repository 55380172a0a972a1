"""End to end: collision measures before (explicit meshes) and after untangling, deformation, time.

Run (a few minutes)::

    python -m benchmarks.outfits [--bodies 3] [--untangler neural] [--threads 2]

For each outfit of the end-to-end issue on ``--bodies`` held-out body shapes (a Sobol seed used by
no training): penetration (largest share of any garment's vertices on the wrong side of an inner
layer, docs/design.md section 7), intersecting triangle pairs between layers (exact tests; total over all
layer pairs), each before (explicit meshes), after the field fit ("fit") and after the exact repair
("repaired", what the service returns), mean vertex displacement of the fit, mean Green strain of
the fitted meshes against the explicit ones, and the time per stage (one request at a time, no cache).
"""

from __future__ import annotations

import argparse

import numpy as np

from service.pipeline.outfit import OutfitModels, make_outfit
from training.drape.dataset import sample_betas

OUTFITS = (
    ("tshirt", "jacket"),
    ("pants", "tshirt", "jacket"),
    ("tank_top", "tshirt", "long_sleeve", "jacket"),
    ("tshirt", "pants"),
    ("shorts", "tank_top"),
)
BODY_SEED = 3


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--bodies", type=int, default=3)
    parser.add_argument("--untangler", choices=("neural", "reference"), default="neural")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args(argv)
    models = OutfitModels.load(threads=args.threads)
    betas = sample_betas(args.bodies, BODY_SEED)
    print(f"## Outfits on {args.bodies} held-out bodies, {args.untangler} untangler")
    print(
        "| outfit | body | penetration before % | fit % | repaired % | intersections before | fit "
        "| repaired | mean displ. mm | mean strain | fields ms | untangle ms | optimise ms | world ms "
        "| repair ms | total ms |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    worst = {"penetration": 0.0, "intersections": 0}
    for ids in OUTFITS:
        for b, beta in enumerate(betas):
            r = make_outfit(models, list(ids), beta, True, args.untangler).report
            s = r["seconds"]
            pen_b = 100 * max(r["penetration_before"].values())
            pen_f = 100 * max(r["penetration_fit"].values())
            pen_a = 100 * max(r["penetration_after"].values())
            int_b = sum(r["intersections_before"].values())
            int_f = sum(r["intersections_fit"].values())
            int_a = sum(r["intersections_after"].values())
            worst["penetration"] = max(worst["penetration"], pen_a)
            worst["intersections"] = max(worst["intersections"], int_a)
            print(
                f"| {', '.join(ids)} | {b} ({', '.join(f'{x:.2f}' for x in beta)}) "
                f"| {pen_b:.2f} | {pen_f:.3f} | {pen_a:.3f} "
                f"| {int_b} | {int_f} | {int_a} | {np.mean(list(r['mean_displacement_mm'].values())):.2f} "
                f"| {np.mean(list(r['mean_green_strain'].values())):.4f} | {1e3 * s['fields']:.0f} "
                f"| {1e3 * s['untangle']:.0f} | {1e3 * s['optimise']:.0f} | {1e3 * s['world']:.0f} "
                f"| {1e3 * s['repair']:.0f} "
                f"| {1e3 * (s['total'] - s.get('quality', 0)):.0f} |"
            )
    print(
        f"\nworst after untangling: penetration {worst['penetration']:.3f} % of a garment's vertices, "
        f"{worst['intersections']} intersecting triangle pairs"
    )


if __name__ == "__main__":
    main()
