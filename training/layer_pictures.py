"""Pictures of the layerings issue 21 asks for: ``python -m training.layer_pictures``.

Writes ``docs/images/layerings.png``: each layering (inner < outer) after untangling, front and side,
on a held-out body (a Sobol seed no training used) and on the box's tallest, heaviest corner (no
training shape either), titled with its crossing pairs, penetration and the worst Green strain p99
against each garment's explicit mesh (``benchmarks.orders.measured``'s measure). A tight garment over a
looser one (the tank top over the T-shirt) presses the inner one in; one whose armholes are higher than
the inner one's (the T-shirt over the jacket) is let down around them (``collisions.junctions``);
a top tucked into pants whose hem hangs below their crotch (the jacket) is gathered up above it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from benchmarks.orders import BODY_SEED
from service.pipeline.outfit import OutfitModels, make_outfit
from service.pipeline.strain import RestShape, green_strain_norms
from service.process.paths import REPO_ROOT
from training.drape.dataset import box_corners, sample_betas
from training.outfit_pictures import layers_of
from training.render import grid, render_views, save_png

LAYERINGS = (
    ("long_sleeve", "tshirt"),  # a T-shirt over a long sleeve
    ("tshirt", "tank_top"),  # a tank top over a T-shirt
    ("long_sleeve", "tank_top"),
    ("jacket", "tshirt"),  # a tight top over a loose one
    ("jacket", "long_sleeve"),  # its sleeves pressed into the narrower ones
    ("jacket", "pants"),  # a long top tucked in: its hem gathered above the crotch
    ("tshirt", "pants"),  # tucked in
    ("pants", "tshirt"),  # worn over
    ("pants", "skirt"),  # a skirt over pants
    ("pants", "shorts"),  # shorts over pants
)


def strain_p99(models: OutfitModels, outfit, ids, beta) -> float:
    explicit = [models.explicit[g].canonical(np.asarray(beta, dtype=np.float64)) for g in ids]
    alone = models.space.to_bodies(explicit, outfit.body_vertices)
    return max(
        float(np.percentile(green_strain_norms(v, RestShape.build(rest, f)), 99))
        for (_, v, f), rest in zip(outfit.garments, alone, strict=True)
    )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "images")
    parser.add_argument("--size", type=int, default=300)
    args = parser.parse_args(argv)
    models = OutfitModels.load()
    corner = box_corners(extremes_only=True)[1]  # gender 0 (male), tallest and heaviest
    bodies = {"held-out": sample_betas(1, BODY_SEED)[0], "tallest, heaviest man": corner}
    images, titles = [], []
    for ids in LAYERINGS:
        for name, beta in bodies.items():
            outfit = make_outfit(models, list(ids), beta, measure=True)
            r = outfit.report
            images.append(render_views(layers_of(outfit), ("front", "side"), args.size))
            pen = 100 * max(r["penetration_after"].values())
            titles.append(f"{' < '.join(ids)}, {name}: {r['crossing_pairs']} crossing pairs, {pen:.2f} % in, "
                          f"strain p99 {strain_p99(models, outfit, ids, beta):.2f}")  # fmt: skip
            print(titles[-1], flush=True)
    path = save_png(args.out / "layerings.png", grid(images, titles, columns=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
