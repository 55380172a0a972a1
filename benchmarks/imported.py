"""An imported garment served with the bundled ones: quality and time per outfit and body.

    python -m benchmarks.imported --garments-dir DIR --id ID [--bodies 4]

Outfits: the garment alone, under and over bundled garments of the other category (and a top over
it for a bottom), on held-out bodies (a Sobol seed no training used) and the four corners of the
supported box at both genders' extremes (shortest and lightest, tallest and heaviest). Per outfit:
collision-free, crossing triangle pairs, largest share of penetrating vertices after the repair,
mean Green strain of the imported garment, total ms (one request at a time, the quality measures
included); then the same per outfit over the bodies.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from service.pipeline.body import SUPPORTED_HEIGHT_PARAM, SUPPORTED_WEIGHT_PARAM
from service.pipeline.catalog import verified_imports
from service.pipeline.outfit import OutfitModels, make_outfit
from training.drape.dataset import sample_betas

BODY_SEED = 3


def corners() -> np.ndarray:
    """(4, 3) betas: each gender at the shortest-lightest and the tallest-heaviest corner."""
    lo = [SUPPORTED_HEIGHT_PARAM[0], SUPPORTED_WEIGHT_PARAM[0]]
    hi = [SUPPORTED_HEIGHT_PARAM[1], SUPPORTED_WEIGHT_PARAM[1]]
    return np.array([[g, *c] for g in (0.0, 1.0) for c in (lo, hi)])


def outfits(models: OutfitModels, gid: str) -> list[tuple[str, ...]]:
    category = models.catalog[gid].category
    if category == "bottom":
        return [(gid,), ("tank_top", gid), (gid, "tshirt"), ("pants", gid), ("tank_top", gid, "jacket")]
    return [(gid,), (gid, "pants"), ("shorts", gid), ("tank_top", gid), (gid, "jacket")]


def main(argv=None) -> None:
    formatter = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=formatter)
    parser.add_argument("--garments-dir", type=Path, required=True)
    parser.add_argument("--id", required=True)
    parser.add_argument("--bodies", type=int, default=4, help="held-out bodies (plus the 4 corners)")
    args = parser.parse_args(argv)
    imported, broken = verified_imports(args.garments_dir)
    if broken:
        raise SystemExit(f"left out, files differ from their manifests: {broken}")
    models = OutfitModels.load(threads=2, imported=imported)
    betas = np.concatenate([sample_betas(args.bodies, BODY_SEED), corners()])
    print(f"## {args.id} (imported) with bundled garments, {args.bodies} held-out bodies + 4 corners")
    print("| outfit | body (gender, height, weight) | collision-free | crossing pairs | penetration % "
          "| strain | ms |")  # fmt: skip
    print("|---|---|---|---:|---:|---:|---:|")
    summary = {}
    for ids in outfits(models, args.id):
        for beta in betas:
            r = make_outfit(models, list(ids), beta, measure=True).report
            pen = 100 * max(r["penetration_after"].values())
            strain, ms = r["mean_green_strain"][args.id], 1e3 * r["seconds"]["total"]
            summary.setdefault(ids, []).append((r["collision_free"], r["crossing_pairs"], pen, strain, ms))
            body = ", ".join(f"{b:.2f}" for b in beta)
            print(f"| {', '.join(ids)} | {body} | {r['collision_free']} | {r['crossing_pairs']} | {pen:.3f} "
                  f"| {strain:.4f} | {ms:.0f} |")  # fmt: skip
    print("\n| outfit | collision-free | worst crossing pairs | worst penetration % | max strain "
          "| median ms |")
    print("|---|---:|---:|---:|---:|---:|")
    for ids, rows in summary.items():
        free, pairs, pen, strain, ms = zip(*rows, strict=True)
        print(f"| {', '.join(ids)} | {sum(free)} of {len(rows)} | {max(pairs)} | {max(pen):.3f} "
              f"| {max(strain):.4f} | {np.median(ms):.0f} |")


if __name__ == "__main__":
    main()
