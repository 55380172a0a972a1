"""Pictures of what each collision stage is for: ``python -m training.collision_pictures``.

Writes ``docs/images/collision_stages.png`` for ``docs/collisions.md``: per stage, the outfit made
without that stage beside the outfit as the service makes it, on a held-out body (a Sobol seed no
training used), front and side, with the triangles that cross an inner layer drawn in red, 1 mm out
along their normals so that they show over the cloth. Titled with the crossing pairs of every pair of
layers, exactly (``service.geometry.intersections``):

- the fit (paper 4.2): the explicit meshes of the per-garment models, tangled, against the fitted ones;
- the let-down: a T-shirt over a jacket whose armholes hang lower, without and with the T-shirt let
  down around them;
- the squeeze: a long top tucked into pants, without and with the top pressed under them;
- the repair: the fitted meshes, which the learned fields leave millimetres off, against the repaired ones.

A stage is left out by replacing it for the one outfit (the let-down's ``PairCaches.lowering``, the
passes' ``_squeeze``) or by ``make_outfit``'s own options (``untangle_layers``, ``repair``).
"""

from __future__ import annotations

import argparse
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from service.geometry.intersections import intersecting_pairs
from service.pipeline.collisions import passes
from service.pipeline.outfit import OutfitModels, make_outfit
from service.process.paths import REPO_ROOT
from training.drape.dataset import sample_betas
from training.outfit_pictures import layers_of
from training.render import MeshLayer, grid, render_views, save_png

CROSSING = (0.85, 0.05, 0.05)
LIFT = 0.001  # m: the red triangles drawn this far out along their normals, over the cloth


def crossing_layer(outfit) -> tuple[MeshLayer | None, int]:
    """(a red layer of every garment triangle that crosses the body or an inner garment, or None; the
    number of crossing pairs over every pair of layers)."""
    meshes = [(outfit.body_vertices, outfit.body_faces)] + [(v, f) for _, v, f in outfit.garments]
    vertices, faces, pairs = [], [], 0
    for i in range(1, len(meshes)):
        v, f = meshes[i]
        hit = []
        for k in range(i):
            found = intersecting_pairs(v, f, *meshes[k])
            pairs += len(found)
            hit.append(found[:, 0])
        tri = f[np.unique(np.concatenate(hit))]
        if len(tri):
            corners = v[tri]  # (T, 3, 3)
            normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
            normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
            vertices.append((corners + LIFT * normal[:, None]).reshape(-1, 3))
            faces.append(np.arange(3 * len(tri)).reshape(-1, 3) + sum(len(x) for x in vertices[:-1]))
    if not vertices:
        return None, pairs
    return MeshLayer(np.concatenate(vertices), np.concatenate(faces), CROSSING, "crossing"), pairs


@contextmanager
def without(owner, name: str, replacement):
    """``owner.name`` replaced by ``replacement`` for the block."""
    kept = getattr(owner, name)
    setattr(owner, name, replacement)
    try:
        yield
    finally:
        setattr(owner, name, kept)


def stages(models: OutfitModels, beta: np.ndarray):
    """(stage, garment ids, outfit without the stage, outfit with it) for every stage, in order."""
    ids = ["tshirt", "jacket"]
    yield ("fit", ids, make_outfit(models, ids, beta, untangle_layers=False, measure=False),
           make_outfit(models, ids, beta, repair=False, measure=False))  # fmt: skip
    ids = ["jacket", "tshirt"]
    with without(models.pairs, "lowering", lambda *asked: None):
        before = make_outfit(models, ids, beta, measure=False)
    yield "let-down", ids, before, make_outfit(models, ids, beta, measure=False)
    ids = ["tshirt", "pants"]
    with without(passes, "_squeeze", lambda stack, fitted, world, *rest: list(world)):
        before = make_outfit(models, ids, beta, measure=False)
    yield "squeeze", ids, before, make_outfit(models, ids, beta, measure=False)
    ids = ["tank_top", "tshirt", "long_sleeve", "jacket"]
    yield ("repair", ids, make_outfit(models, ids, beta, repair=False, measure=False),
           make_outfit(models, ids, beta, measure=False))  # fmt: skip


def main(argv=None) -> None:
    formatter = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=formatter)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "images")
    parser.add_argument("--size", type=int, default=300)
    args = parser.parse_args(argv)
    models = OutfitModels.load()
    models.warm()
    beta = sample_betas(2, 3)[1]
    images, titles = [], []
    for stage, ids, before, after in stages(models, beta):
        for state, outfit in ((f"without the {stage}", before), (f"with the {stage}", after)):
            red, pairs = crossing_layer(outfit)
            layers = layers_of(outfit) + ([red] if red is not None else [])
            images.append(render_views(layers, ("front", "side"), args.size))
            titles.append(f"{' < '.join(ids)}, {state}: {pairs} crossing pairs")
            print(titles[-1], flush=True)
    path = save_png(args.out / "collision_stages.png", grid(images, titles, columns=2))
    print(f"wrote {path} (beta {np.round(beta, 3).tolist()})")


if __name__ == "__main__":
    main()
