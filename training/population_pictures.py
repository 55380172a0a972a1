"""Pictures of real adults' bodies, undressed and dressed (issue 55), for docs/body.md.

    python -m training.population_pictures [--size 300]

People are NHANES held-out adults (``benchmarks.population``), chosen by BMI and height across the
population (``PEOPLE``: the held-out adult nearest each (sex, BMI, height)), built from their height,
weight and hip girth as a shopper would give them. Writes ``docs/images/population_bodies.png`` (front
and side) and ``docs/images/population_outfits.png`` (``OUTFIT`` on each; triangles crossing the body or
an inner layer in red, as in ``training.collision_pictures``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from benchmarks import population
from service.pipeline.body_build import BodyRequest
from service.pipeline.dressed_body import dressed_vertices
from service.pipeline.models import OutfitModels
from service.pipeline.outfit import make_outfit
from service.process.paths import REPO_ROOT
from training.collision_pictures import crossing_layer
from training.outfit_pictures import layers_of
from training.render import PALETTE, MeshLayer, grid, render_views, save_png

# (sex, BMI, height cm): thin to very heavy, short to tall.
PEOPLE = (
    ("female", 18.5, 160.0),
    ("female", 25.0, 150.0),
    ("female", 32.0, 170.0),
    ("female", 40.0, 160.0),
    ("female", 55.0, 165.0),
    ("male", 19.0, 180.0),
    ("male", 26.0, 165.0),
    ("male", 33.0, 190.0),
    ("male", 42.0, 175.0),
    ("male", 52.0, 180.0),
)
OUTFIT = ("pants", "tshirt", "jacket")


def nearest_people() -> list[dict]:
    """The held-out adult nearest each of ``PEOPLE`` (BMI in units of 1, height in units of 5 cm)."""
    out = []
    for sex, bmi, height in PEOPLE:
        _, held = population.split(population.load(sex))
        k = int(np.argmin(np.abs(held.bmi - bmi) + np.abs(held.height_cm - height) / 5.0))
        out.append(
            {
                "sex": sex,
                "gender": held.gender,
                "height_cm": float(held.height_cm[k]),
                "weight_kg": float(held.weight_kg[k]),
                "hip_cm": float(held.columns["BMXHIP"][k]),
                "bmi": float(held.bmi[k]),
            }
        )
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=300)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "images")
    args = parser.parse_args(argv)
    models = OutfitModels.load()
    bodies, dressed = [], []
    for p in nearest_people():
        built = models.bodies.build(
            BodyRequest(p["gender"], p["height_cm"], p["weight_kg"], hip_cm=p["hip_cm"])
        )
        v = built.vertices
        m = built.measured
        sex = p["sex"][0].upper()
        title = f"{sex} {m.height_cm:.0f} cm {m.weight_kg:.0f} kg BMI {p['bmi']:.0f} hip {m.hip_cm:.0f}"
        bodies.append(
            render_views(
                [MeshLayer(v, models.body.faces, PALETTE["skin"])], ("front", "side"), args.size, title=title
            )
        )
        worn = dressed_vertices(models.body, built)  # as the service dresses it: contacts opened for cloth
        outfit = make_outfit(models, list(OUTFIT), built.garment_beta, measure=False, body_vertices=worn)
        red, pairs = crossing_layer(outfit)
        layers = layers_of(outfit) + ([red] if red is not None else [])
        dressed.append(render_views(layers, ("front", "side"), args.size, title=f"{title}, {pairs} crossing"))
        print(
            title, "crossing pairs", pairs, "collision_free", outfit.report.get("collision_free"), flush=True
        )
    save_png(args.out / "population_bodies.png", grid(bodies, columns=5))
    save_png(args.out / "population_outfits.png", grid(dressed, columns=5))
    print(f"wrote {args.out / 'population_bodies.png'} and {args.out / 'population_outfits.png'}")


if __name__ == "__main__":
    main()
