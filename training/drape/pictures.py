"""Pictures of the drape dataset and the explicit models: ``python -m training.drape.pictures``.

Writes to ``docs/images``:
- ``drape_<id>.png``: the garment simulated on the four most contrasting dataset bodies;
- ``explicit_vs_simulation.png``: explicit-model prediction beside the simulation on held-out
  shapes, with the mean vertex error in the title.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from service.pipeline.body import DEFAULT_BETA, BodyModel, body_measurements
from service.pipeline.canonical import CanonicalSpace
from service.pipeline.explicit import ExplicitModel
from service.process.paths import REPO_ROOT
from training.drape.dataset import DEFAULT_DIR, load_split, split_body_vertices
from training.pictures import GARMENT_COLORS
from training.render import PALETTE, MeshLayer, grid, render_views, save_png

# Corners of the (gender, height, weight) box the pictures look for in the dataset.
CONTRAST = ((0.0, 1.0, 1.0), (0.0, 0.0, 0.0), (1.0, 1.0, 0.0), (1.0, 0.0, 1.0))


def contrasting(betas: np.ndarray, count: int = 4) -> list[int]:
    """Indices of the shapes ``(B, 3)`` nearest to the CONTRAST corners of their bounding box."""
    lo, hi = betas.min(axis=0), betas.max(axis=0)
    unit = (betas - lo) / np.maximum(hi - lo, 1e-9)
    return [int(np.argmin(np.linalg.norm(unit - np.array(c), axis=1))) for c in CONTRAST[:count]]


def _label(body: BodyModel, beta: np.ndarray, vertices: np.ndarray) -> str:
    h, w = body_measurements(vertices, body.faces)
    sex = "female" if beta[0] > 0.5 else "male"
    return f"{sex} g={beta[0]:.2f}, {100 * h:.0f} cm, {w:.0f} kg, BMI {w / h**2:.0f}"


def drape_picture(body: BodyModel, data: dict, garment_id: str, faces: np.ndarray) -> np.ndarray:
    images, titles = [], []
    color = GARMENT_COLORS.get(garment_id, PALETTE["rose"])
    bodies = split_body_vertices(body, data)
    for i in contrasting(data["beta"]):
        beta = data["beta"][i]
        layers = [
            MeshLayer(bodies[i], body.faces, PALETTE["skin"]),
            MeshLayer(data["world"][i], faces, color),
        ]
        images.append(render_views(layers, ("front", "side"), 380))
        titles.append(_label(body, beta, bodies[i]))
    return grid(images, titles, columns=2)


def comparison_picture(
    body: BodyModel, space: CanonicalSpace, data_dir: Path, ids: list[str], faces: dict
) -> np.ndarray:
    images, titles = [], []
    for gid in ids:
        test = load_split(data_dir, "test", gid)
        model = ExplicitModel.load(gid)
        bodies = split_body_vertices(body, test)
        for i in contrasting(test["beta"], 2):
            beta = test["beta"][i]
            b = bodies[i]
            pred = space.to_body(model.canonical(beta), b)
            err = np.linalg.norm(pred - test["world"][i], axis=1).mean() * 1e3
            skin = MeshLayer(b, body.faces, PALETTE["skin"])
            for name, v, color in (
                ("explicit model", pred, PALETTE["sage"]),
                ("simulation", test["world"][i], PALETTE["brick"]),
            ):
                images.append(render_views([skin, MeshLayer(v, faces[gid], color)], ("front", "side"), 300))
                titles.append(
                    f"{gid} {name}: {_label(body, beta, b)}"
                    + (f", mean error {err:.1f} mm" if name[0] == "e" else "")
                )
    return grid(images, titles, columns=2)


def main(argv=None) -> None:
    from service.pipeline.catalog import load_catalog

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--data", type=Path, default=DEFAULT_DIR)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "images")
    parser.add_argument("--garments", default="tshirt,skirt")
    args = parser.parse_args(argv)
    ids = args.garments.split(",")
    body = BodyModel.load()
    catalog = load_catalog()
    for gid in ids:
        splits = [load_split(args.data, s, gid) for s in ("train", "test")]
        keys = [k for k in ("beta", "world", "body") if k in splits[0]]
        data = {k: np.concatenate([s[k] for s in splits]) for k in keys}
        save_png(args.out / f"drape_{gid}.png", drape_picture(body, data, gid, catalog[gid].faces))
    space = CanonicalSpace.build(body.vertices(np.asarray(DEFAULT_BETA)), body.faces)
    faces = {gid: catalog[gid].faces for gid in ids}
    save_png(args.out / "explicit_vs_simulation.png", comparison_picture(body, space, args.data, ids, faces))
    print(f"wrote pictures to {args.out}")


if __name__ == "__main__":
    main()
