"""What textures add to an outfit's GLB: bytes with flat colours against bytes with UVs and textures.

    python -m benchmarks.glb_size

The outfits of ``benchmarks.outfits`` with the body, explicit meshes (the size does not depend on
the fit), written once as flat-colour layers and once with each garment's display mesh and material.
"""

from __future__ import annotations

import numpy as np

from benchmarks.outfits import OUTFITS
from service.pipeline.body import DEFAULT_BETA
from service.pipeline.gltf import outfit_glb
from service.pipeline.outfit import OutfitModels, make_outfit
from service.pipeline.tryon import glb_layers


def main() -> None:
    models = OutfitModels.load(threads=2)
    print("| outfit | flat colours MB | textured MB | textures embedded | ratio |")
    print("|---|---:|---:|---:|---:|")
    for ids in OUTFITS:
        beta = np.asarray(DEFAULT_BETA)
        outfit = make_outfit(models, list(ids), beta, untangle_layers=False, measure=False)
        body = (outfit.body_vertices, outfit.body_faces)
        flat = outfit_glb(glb_layers(outfit.garments, {}, body))
        textured = outfit_glb(glb_layers(outfit.garments, models.catalog, body))
        images = sum(len(t) for g in ids for t in models.catalog[g].material.textures.values())
        print(f"| {', '.join(ids)} | {len(flat) / 1e6:.2f} | {len(textured) / 1e6:.2f} | "
              f"{images / 1e3:.0f} kB | {len(textured) / len(flat):.2f} |")  # fmt: skip


if __name__ == "__main__":
    main()
