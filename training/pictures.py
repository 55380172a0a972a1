"""Pictures of the body model and the catalog: ``python -m training.pictures [out_dir]``.

Writes to ``docs/images`` by default: ``bodies.png`` (contrasting shapes, front and side),
``garment_<id>.png`` (each garment on the mean body, front and side) and ``catalog.png``
(the whole catalog in one grid). Takes about a minute on 2 cores.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from service.pipeline.body import DEFAULT_BETA, BodyModel, measurements_from_shape
from service.pipeline.catalog import load_catalog
from service.process.paths import REPO_ROOT
from training.render import PALETTE, MeshLayer, grid, render, render_views, save_png

GARMENT_COLORS = {
    "tank_top": PALETTE["mustard"],
    "tshirt": PALETTE["brick"],
    "long_sleeve": PALETTE["sage"],
    "jacket": PALETTE["charcoal"],
    "pants": PALETTE["denim"],
    "shorts": PALETTE["teal"],
    "skirt": PALETTE["plum"],
}
# (label, beta = gender, height, weight) spanning the supported box
BODY_SHAPES = (
    ("male, tall, heavy", (0.0, 0.65, 0.95)),
    ("male, short, slim", (0.0, 0.2, 0.05)),
    ("mean", DEFAULT_BETA),
    ("female, tall, slim", (1.0, 0.65, 0.1)),
    ("female, short, heavy", (1.0, 0.2, 0.95)),
)


def body_pictures(body: BodyModel, size: int = 420) -> np.ndarray:
    images, titles = [], []
    for label, beta in BODY_SHAPES:
        v = body.vertices(np.array(beta))
        height_cm, mass_kg = measurements_from_shape(body, np.array(beta))
        images.append(render_views([MeshLayer(v, body.faces, PALETTE["skin"])], ("front", "side"), size))
        titles.append(f"{label}: {height_cm:.0f} cm, {mass_kg:.0f} kg")
    return grid(images, titles, columns=3)


def main(out_dir: Path) -> None:
    body = BodyModel.load()
    mean = body.vertices(np.array(DEFAULT_BETA))
    skin = MeshLayer(mean, body.faces, PALETTE["skin"], "body")
    save_png(out_dir / "bodies.png", body_pictures(body))
    fronts, titles = [], []
    for gid, g in load_catalog().items():
        layer = MeshLayer(g.vertices, g.faces, GARMENT_COLORS.get(gid, PALETTE["rose"]), gid)
        title = f"{g.name} ({gid}): {len(g.vertices)} vertices, openings {', '.join(sorted(g.openings))}"
        save_png(out_dir / f"garment_{gid}.png",
                 render_views([skin, layer], ("front", "side", "back"), size=480, title=title))
        fronts.append(render([skin, layer], "three_quarter", size=420))
        titles.append(gid)
    save_png(out_dir / "catalog.png", grid(fronts, titles, columns=4))
    print(f"wrote pictures to {out_dir}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else REPO_ROOT / "docs" / "images")
