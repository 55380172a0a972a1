"""Heavy bodies whose parts cross, before and after they are pressed into contact (issue 55), for
docs/body.md.

    python -m training.self_contact_pictures [--size 360]

Held-out NHANES adults (``benchmarks.population``) nearest each of ``PEOPLE``, built from height,
weight and hip as a shopper gives them. Each row: the torso and thighs of the body as Anny's shape
makes it, crossing triangles in red, then the mesh the service serves (``body_build.pressed_body``),
front and back. Writes ``docs/images/self_contact.png``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from benchmarks import population
from service.geometry.mesh import vertex_normals
from service.geometry.self_contact import self_crossings
from service.pipeline.body_build import BodyRequest
from service.pipeline.models import OutfitModels
from service.process.paths import REPO_ROOT
from training.render import MeshLayer, grid, render_views, save_png

PEOPLE = (("female", 42.0, 160.0), ("female", 60.0, 161.0), ("male", 54.0, 171.0))  # (sex, BMI, cm)
SKIN = (0.80, 0.70, 0.60)
RED = (0.9, 0.1, 0.1)
LIFT = 0.002  # m: red triangles drawn this far out along their normals
TORSO_Z = (-0.45, 0.45)  # m: the part drawn (knees to shoulders, Anny's frame)


def _torso(vertices: np.ndarray, faces: np.ndarray, marked: np.ndarray | None) -> list[MeshLayer]:
    z = vertices[faces].mean(axis=1)[:, 2]
    keep = (z > TORSO_Z[0]) & (z < TORSO_Z[1])
    layers = [MeshLayer(vertices, faces[keep], SKIN)]
    if marked is not None and np.any(marked & keep):
        lifted = vertices + LIFT * vertex_normals(vertices, faces)
        layers.append(MeshLayer(lifted, faces[marked & keep], RED))
    return layers


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=360)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "images" / "self_contact.png")
    args = parser.parse_args(argv)
    models = OutfitModels.load()
    builder, faces = models.bodies, models.body.faces
    images, titles = [], []
    for sex, bmi, height in PEOPLE:
        _, held = population.split(population.load(sex))
        k = int(np.argmin(np.abs(held.bmi - bmi) + np.abs(held.height_cm - height) / 5.0))
        request = BodyRequest(held.gender, float(held.height_cm[k]), float(held.weight_kg[k]),
                              hip_cm=float(held.columns["BMXHIP"][k]))  # fmt: skip
        built = builder.build(request)
        raw = models.body.shape_vertices(built.shape)
        pairs = self_crossings(raw, faces, models.body.template_crossings)
        marked = np.zeros(len(faces), dtype=bool)
        marked[pairs.ravel()] = True
        left = len(self_crossings(built.vertices, faces, models.body.template_crossings))
        label = f"{sex}, BMI {held.bmi[k]:.0f}, {held.height_cm[k]:.0f} cm"
        images.append(render_views(_torso(raw, faces, marked), ("front", "back"), args.size))
        titles.append(f"{label}: as grown, {len(pairs)} crossing pairs")
        images.append(render_views(_torso(built.vertices, faces, None), ("front", "back"), args.size))
        titles.append(f"as served, pressed: {left} left")
    save_png(args.out, grid(images, titles, columns=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
