"""Pictures of outfits before and after untangling (paper Figure 3): ``python -m training.outfit_pictures``.

Writes ``docs/images/outfits.png``: per outfit, the explicit meshes as the per-garment models put
them (tangled) beside the untangled result, front and side views, on a held-out body; the T-shirt
appears both tucked into the pants and over them.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from service.pipeline.outfit import OutfitModels, make_outfit
from service.process.paths import REPO_ROOT
from training.drape.dataset import sample_betas
from training.pictures import GARMENT_COLORS
from training.render import PALETTE, MeshLayer, grid, render_views, save_png

OUTFITS = (
    ("tshirt", "jacket"),
    ("tshirt", "pants"),
    ("pants", "tshirt"),
    ("tank_top", "tshirt", "long_sleeve", "jacket"),
)


def layers_of(outfit) -> list[MeshLayer]:
    out = [MeshLayer(outfit.body_vertices, outfit.body_faces, PALETTE["skin"])]
    for gid, v, f in outfit.garments:
        out.append(MeshLayer(v, f, GARMENT_COLORS.get(gid, PALETTE["rose"])))
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "images")
    parser.add_argument("--size", type=int, default=360)
    parser.add_argument("--untangler", choices=("neural", "reference"), default="neural")
    args = parser.parse_args(argv)
    models = OutfitModels.load()
    beta = sample_betas(2, 3)[1]
    images, titles = [], []
    for ids in OUTFITS:
        for untangle in (False, True):
            outfit = make_outfit(models, list(ids), beta, untangle, args.untangler, measure=untangle)
            images.append(render_views(layers_of(outfit), ("front", "side"), args.size))
            r = outfit.report
            state = f"untangled ({args.untangler})" if untangle else "explicit models only (before)"
            detail = ""
            if untangle:
                pen_b = 100 * max(r["penetration_before"].values())
                pen_a = 100 * max(r["penetration_after"].values())
                int_b, int_a = (sum(r[f"intersections_{k}"].values()) for k in ("before", "after"))
                detail = f": penetration {pen_b:.1f} -> {pen_a:.2f} %, intersections {int_b} -> {int_a}"
            titles.append(f"{' < '.join(ids)}, {state}{detail}")
    save_png(args.out / "outfits.png", grid(images, titles, columns=2))
    print(f"wrote {args.out / 'outfits.png'} (beta {np.round(beta, 3).tolist()})")


if __name__ == "__main__":
    main()
