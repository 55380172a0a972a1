"""Give the procedural garments their look: UVs (``training.garments.uv``) and fabric textures made
by code (``training.garments.fabric``). ``python -m training.garments.appearance`` dresses the
committed catalog in place (seconds; the simulation meshes are untouched); ``python -m
training.garments`` does it for every garment it builds.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from service.pipeline.appearance import Material
from service.pipeline.body import BodyModel
from service.pipeline.catalog import Garment, load_catalog, save_garment
from service.pipeline.gltf import COLORS
from service.process.paths import models_dir
from training.garments.fabric import Fabric, base_color, normal_map
from training.garments.uv import cylinder_uv
from training.render import png_bytes

# Yarn colours are the flat colours the outfits had before (service.pipeline.gltf.COLORS).
FABRICS: dict[str, Fabric] = {
    "tank_top": Fabric("rib", COLORS["tank_top"], tile=0.04),
    "tshirt": Fabric("jersey", COLORS["tshirt"], tile=0.04),
    "long_sleeve": Fabric("jersey", COLORS["long_sleeve"], tile=0.04),
    "jacket": Fabric("twill", COLORS["jacket"], tile=0.05, roughness=0.8),
    "pants": Fabric("denim", COLORS["pants"], tile=0.05, roughness=0.85),
    "shorts": Fabric("denim", COLORS["shorts"], tile=0.05, roughness=0.85),
    "skirt": Fabric("twill", COLORS["skirt"], tile=0.05),
}


def dress(garment: Garment, body: BodyModel, fabric: Fabric) -> Garment:
    """``garment`` with a display mesh on ``body``'s mean shape and a material of ``fabric``."""
    display = cylinder_uv(garment.vertices, garment.faces, body, fabric.tile)
    material = Material(
        base_color=(1.0, 1.0, 1.0, 1.0),  # the colour is in the texture
        roughness=fabric.roughness,
        textures={"base_color": png_bytes(base_color(fabric)), "normal": png_bytes(normal_map(fabric))},
        texture_files={"base_color": f"{garment.id}.base.png", "normal": f"{garment.id}.normal.png"},
    )
    return replace(garment, display=display, material=material)


def write_catalog(directory: Path, garments: list[Garment]) -> Path:
    """``catalog.json`` listing ``garments`` in order."""
    path = directory / "catalog.json"
    path.write_text(json.dumps({"garments": [g.catalog_entry() for g in garments]}, indent=2) + "\n")
    return path


def main(argv=None) -> None:
    formatter = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=formatter)
    parser.add_argument("--garments", type=Path, default=None, help="default: models/garments")
    args = parser.parse_args(argv)
    directory = args.garments or models_dir() / "garments"
    body = BodyModel.load()
    dressed = []
    for garment in load_catalog(directory).values():
        fabric = FABRICS[garment.id]
        dressed.append(dress(garment, body, fabric))
        save_garment(directory, dressed[-1])
        n = len(dressed[-1].display.source)
        print(f"{garment.id:12s} {fabric.weave:7s} {n} display vertices for {len(garment.vertices)}")
    write_catalog(directory, dressed)
    load_catalog.cache_clear()


if __name__ == "__main__":
    main()
