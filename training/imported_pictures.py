"""Pictures of an imported garment as the service returns it, textured, on four bodies.

    python -m training.imported_pictures --garments-dir DIR --id ID [--with tank_top] [--out docs/images]

The outfits (the imported garment and ``--with`` bundled garments, inner to outer, untangled: a garment
worn from the waist down outermost, any other innermost, ``collisions.traits``) on two
held-out bodies and two corners of the supported box are rendered by the page's own viewer in
headless Chromium (``tests/js/glb_views.mjs``: needs node, ``tests/js/node_modules`` and chromium,
as ``make test`` installs), front and back, into ``OUT/imported_<id>.png``.
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from service.pipeline.catalog import verified_imports
from service.pipeline.collisions.layering import LayeringRule
from service.pipeline.collisions.traits import traits_of
from service.pipeline.gltf import outfit_glb
from service.pipeline.outfit import OutfitModels, make_outfit
from service.pipeline.tryon import glb_layers
from training.drape.dataset import sample_betas

JS = Path(__file__).resolve().parents[1] / "tests" / "js"
BODIES = np.concatenate([sample_betas(2, 3), [[0.0, 0.72, 1.0], [1.0, 0.12, 0.0]]])


def main(argv=None) -> None:
    from PIL import Image

    formatter = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=formatter)
    parser.add_argument("--garments-dir", type=Path, required=True)
    parser.add_argument("--id", required=True)
    parser.add_argument("--with", dest="others", default="tank_top", help="comma-separated, inner to outer")
    parser.add_argument("--out", type=Path, default=Path("docs/images"))
    args = parser.parse_args(argv)
    models = OutfitModels.load(threads=2, imported=verified_imports(args.garments_dir)[0])
    ids = [g for g in args.others.split(",") if g]
    # Worn from the waist down: over the tops, tucked in; else (a top, a dress) under the others.
    rule = LayeringRule(models.space.mean_vertices, models.space.faces)
    waist_down = not traits_of(rule, models.catalog[args.id]).covers_chest
    ids = [*ids, args.id] if waist_down else [args.id, *ids]
    with tempfile.TemporaryDirectory() as tmp:
        files = []
        for i, beta in enumerate(BODIES):
            outfit = make_outfit(models, ids, beta)
            body = (outfit.body_vertices, outfit.body_faces)
            files.append(Path(tmp) / f"body{i}.glb")
            files[-1].write_bytes(outfit_glb(glb_layers(outfit.garments, models.catalog, body)))
        rows = []
        for orbit in ("15deg 80deg auto", "195deg 80deg auto"):
            command = ["node", str(JS / "glb_views.mjs"), tmp, orbit, *map(str, files)]
            subprocess.run(command, check=True, cwd=JS)
            rows.append([Image.open(f.with_suffix(".png")).convert("RGB") for f in files])
        w, h = rows[0][0].size
        sheet = Image.new("RGB", (w * len(files), h * len(rows)), "white")
        for r, row in enumerate(rows):
            for c, image in enumerate(row):
                sheet.paste(image, (c * w, r * h))
        args.out.mkdir(parents=True, exist_ok=True)
        path = args.out / f"imported_{args.id}.png"
        sheet.resize((sheet.width // 2, sheet.height // 2)).save(path)
        print(f"wrote {path}: {', '.join(ids)} on bodies {np.round(BODIES, 2).tolist()}")


if __name__ == "__main__":
    main()
