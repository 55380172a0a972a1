"""Pictures of one style in several sizes on one body, with their tension maps (issue 56):
``python -m training.size_pictures [--garment tshirt] [--sizes S,M,L,XL] [--body 0,178,80]``;
``--charts``: the chart bodies of every size instead (``docs/images/chart_bodies.png``);
``--over tank_top,long_sleeve``: the garment in the first of ``--sizes`` over each of these, as the
service answers it, with the tension maps (``docs/images/layers_<garment>.png``).

Each size is its rest shape (``training.garments.grading``: the style's pattern on the size's chart
body, ``models/garments/size_charts.json``). Per size, left to right: draped on the shopper's body by
the drape simulation (``training.drape.dataset.drape_garment`` with ``rest_body``), its tension map,
then what the service answers for ``{"id": garment, "size": letter}`` (explicit model, size model, fit
and repair) and its tension map (``service.pipeline.tension``: each triangle's largest principal
strain against the size's rest shape, white at rest or slack, through yellow to red at
``MAP_STRAIN``). Writes ``docs/images/sizes_<garment>.png`` and the drapes to ``build/size_drapes/``
(kept: a drape takes 30-120 s).
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
from service.pipeline.tension import CutShapes, tension_colors
from service.pipeline.tryon import ModelEngine, OutfitSpec
from service.process.paths import REPO_ROOT, models_dir
from training.drape.dataset import drape_garment
from training.drape.solve import DrapeSettings
from training.garments.grading import (
    CHARTS_NAME,
    DEFAULT_RUN,
    STYLE_RUNS,
    chart_builder,
    chart_vertices,
)
from training.pictures import GARMENT_COLORS
from training.render import PALETTE, MeshLayer, fit_camera, grid, render, render_views, save_png

DRAPES = REPO_ROOT / "build" / "size_drapes"


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


def layers_picture(args) -> Path:
    """The garment in its first size over each of ``args.over``, served, plain and as tension maps."""
    gender, height, weight = (float(x) for x in args.body.split(","))
    engine = ModelEngine.load(models_dir(), threads=2)
    letter = args.sizes.split(",")[0]
    images, titles = [], []
    for inner in args.over.split(","):
        spec = OutfitSpec((inner, args.garment), gender, height, weight, sizes=(None, letter), tension=True)
        result = engine.make(spec)
        body, *garments = result.layers
        skin = MeshLayer(body.vertices, body.faces, PALETTE["skin"])
        plain = [skin, *(MeshLayer(g.vertices, g.faces, GARMENT_COLORS.get(g.name, PALETTE["rose"]))
                         for g in garments)]  # fmt: skip
        mapped = [skin, *(MeshLayer(g.vertices, g.faces, PALETTE["rose"],
                                    face_colors=np.asarray(g.colors)[np.asarray(g.faces)].mean(axis=1))
                          for g in garments)]  # fmt: skip
        camera = fit_camera(plain, "front")
        images.append(np.concatenate([render(plain, "front", 420, camera=camera),
                                      render(mapped, "front", 420, camera=camera)], axis=1))  # fmt: skip
        t = result.report["tension"][args.garment]
        titles.append(f"{args.garment} {letter} over {inner}: stretch median {100 * t['stretch_p50']:.1f} %, "
                      f"{100 * t['stretched_share']:.0f} % of it over 2 %")
    return save_png(args.out / f"layers_{args.garment}.png", grid(images, titles, columns=2))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--garment", default="tshirt")
    parser.add_argument("--sizes", default="S,M,L,XL")
    parser.add_argument("--body", default="0,178,80", help="gender,height_cm,weight_kg")
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "images")
    parser.add_argument("--charts", action="store_true", help="the chart bodies instead (chart_bodies.png)")
    parser.add_argument("--over", default="", help="inner garments to wear it over, one picture each")
    args = parser.parse_args(argv)
    if args.over:
        print(f"wrote {layers_picture(args)}")
        return
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
    engine = ModelEngine.load(models_dir(), threads=2)
    cuts = CutShapes(engine.models)
    images, titles = [], []
    for letter in args.sizes.split(","):
        record = charts[f"{run}/{letter}"]
        chart_body = chart_vertices(builder, record)
        cache = DRAPES / f"{args.garment}_{letter}_{gender:g}_{height:g}_{weight:g}.npz"
        drape = drape_size(garment, body, model.faces, space, chart_body, cache)
        spec = OutfitSpec((args.garment,), gender, height, weight, sizes=(letter,), include_body=False)
        served = engine.make(spec).layers[0].vertices
        row, strains = [], []
        for world in (drape, served):
            stretch = cuts.stretch(args.garment, letter, built.vertices, world)
            faces = np.asarray(garment.faces)
            face_stretch = stretch[faces].mean(axis=1)
            layers = [skin, MeshLayer(world, garment.faces, color)]
            camera = fit_camera(layers, "front")
            tension = [skin, MeshLayer(world, garment.faces, color, face_colors=tension_colors(face_stretch))]
            row += [render(layers, "front", 360, camera=camera), render(tension, "front", 360, camera=camera)]
            strains.append(100 * np.median(stretch))
        images.append(np.concatenate(row, axis=1))
        girth = "hip" if garment.category == "bottom" else "chest"  # the girth its size is read by
        cut, worn = record["row"][f"{girth}_cm"], getattr(built.measured, f"{girth}_cm")
        titles.append(f"{args.garment} {letter} (cut for {girth} {cut:g} cm) on {girth} {worn:.0f} cm: "
                      f"simulated (stretch p50 {strains[0]:.1f} %), served ({strains[1]:.1f} %)")
    out = save_png(args.out / f"sizes_{args.garment}.png", grid(images, titles, columns=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
