"""Pictures of one style in several sizes simulated on one body, with their tension maps (issue 56):
``python -m training.size_pictures [--garment tshirt] [--sizes S,M,L,XL] [--body 0,178,80]``;
``--charts``: the chart bodies of every size instead (``docs/images/chart_bodies.png``).

Each size is its rest shape (``training.garments.grading``: the style's pattern on the size's chart
body, ``models/garments/size_charts.json``) draped on the shopper's body by the drape simulation
(``training.drape.dataset.drape_garment`` with ``rest_body``), not the garment models. Beside each
drape, its tension map: each triangle's largest principal strain against the size's rest shape
(``service.pipeline.ease.principal_strain``), white where the cloth is at its rest length or shorter,
through yellow to red at ``MAP_STRAIN`` stretched. Writes ``docs/images/sizes_<garment>.png`` and the
drapes to ``build/size_drapes/`` (kept: a drape takes 30-120 s).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.body_build import BodyRequest
from service.pipeline.canonical import CanonicalSpace
from service.pipeline.catalog import load_catalog
from service.pipeline.dressed_body import dressed_vertices
from service.pipeline.ease import principal_strain
from service.pipeline.strain import RestShape
from service.process.paths import REPO_ROOT, models_dir
from training.drape.dataset import drape_garment
from training.drape.solve import DrapeSettings
from training.garments.grading import (
    CHARTS_NAME,
    DEFAULT_RUN,
    STYLE_RUNS,
    chart_builder,
    chart_vertices,
    graded_rest,
)
from training.pictures import GARMENT_COLORS
from training.render import PALETTE, MeshLayer, fit_camera, grid, render, render_views, save_png

MAP_STRAIN = 0.15  # the tension map's full red: 15 % stretched
DRAPES = REPO_ROOT / "build" / "size_drapes"


RAMP = ((0.0, (0.95, 0.95, 0.95)), (0.33, (0.98, 0.85, 0.2)), (1.0, (0.8, 0.05, 0.05)))  # white, yellow, red


def tension_colors(strain: np.ndarray) -> np.ndarray:
    """``(F, 3)`` RGB of ``strain (F,)``: white at 0 or less, yellow at a third of ``MAP_STRAIN``, red
    at it and more."""
    t = np.clip(strain / MAP_STRAIN, 0.0, 1.0)
    stops = np.array([s for s, _ in RAMP])
    colors = np.array([c for _, c in RAMP])
    return np.stack([np.interp(t, stops, colors[:, k]) for k in range(3)], axis=1)


def drape_size(garment, body: np.ndarray, faces: np.ndarray, space, chart_body: np.ndarray, cache: Path):
    """The drape ``(V, 3)`` of one size on ``body``, kept in ``cache`` (npz)."""
    if cache.exists():
        return np.load(cache)["world"]
    d = drape_garment(garment, body, faces, space, DrapeSettings(), rest_body=chart_body)
    cache.parent.mkdir(parents=True, exist_ok=True)
    np.savez(cache, world=d.world)
    return d.world


def chart_picture(builder, charts: dict) -> np.ndarray:
    """Every chart body, front and side, titled with what it measures."""
    images, titles = [], []
    for key, record in charts.items():
        body = chart_vertices(builder, record)
        skin = MeshLayer(body, builder.model.faces, PALETTE["skin"])
        images.append(render_views([skin], ("front", "side"), 260))
        b = record["body"]
        titles.append(f"{key.replace('/', ' ')}: {b['height_cm']:g} cm {b['weight_kg']:g} kg, "
                      f"{b['chest_cm']:g}/{b['waist_cm']:g}/{b['hip_cm']:g}")  # fmt: skip
    return grid(images, titles, columns=6)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--garment", default="tshirt")
    parser.add_argument("--sizes", default="S,M,L,XL")
    parser.add_argument("--body", default="0,178,80", help="gender,height_cm,weight_kg")
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "images")
    parser.add_argument("--charts", action="store_true", help="the chart bodies instead (chart_bodies.png)")
    args = parser.parse_args(argv)
    if args.charts:
        builder = chart_builder()
        charts = json.loads((models_dir() / "garments" / CHARTS_NAME).read_text())
        print(f"wrote {save_png(args.out / 'chart_bodies.png', chart_picture(builder, charts))}")
        return
    gender, height, weight = (float(x) for x in args.body.split(","))
    builder = chart_builder()
    model: BodyModel = builder.model
    built = builder.build(BodyRequest(gender, height, weight))
    body = dressed_vertices(model, built)
    garment = load_catalog()[args.garment]
    space = CanonicalSpace.build(model.vertices(np.asarray(DEFAULT_BETA)), model.faces)
    charts = json.loads((models_dir() / "garments" / CHARTS_NAME).read_text())
    run = STYLE_RUNS.get(args.garment, DEFAULT_RUN)
    skin = MeshLayer(body, model.faces, PALETTE["skin"])
    color = GARMENT_COLORS.get(args.garment, PALETTE["rose"])
    images, titles = [], []
    for letter in args.sizes.split(","):
        record = charts[f"{run}/{letter}"]
        chart_body = chart_vertices(builder, record)
        cache = DRAPES / f"{args.garment}_{letter}_{gender:g}_{height:g}_{weight:g}.npz"
        world = drape_size(garment, body, model.faces, space, chart_body, cache)
        rest = graded_rest(space, garment.vertices, chart_body)
        strain = principal_strain(world, RestShape.build(rest, garment.faces))
        layers = [skin, MeshLayer(world, garment.faces, color)]
        camera = fit_camera(layers, "front")
        tension = [skin, MeshLayer(world, garment.faces, color, face_colors=tension_colors(strain))]
        images.append(np.concatenate([render(layers, "front", 420, camera=camera),
                                      render(tension, "front", 420, camera=camera)], axis=1))  # fmt: skip
        p95 = 100 * np.percentile(strain, 95)
        girth = "hip" if garment.category == "bottom" else "chest"  # the girth its size is read by
        cut, worn = record["row"][f"{girth}_cm"], getattr(built.measured, f"{girth}_cm")
        titles.append(f"{args.garment} {letter} (cut for {girth} {cut:g} cm) on {girth} {worn:.0f} cm: "
                      f"strain p95 {p95:.0f} %")
    out = save_png(args.out / f"sizes_{args.garment}.png", grid(images, titles, columns=2))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
