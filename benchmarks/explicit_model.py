"""Drape dataset and explicit garment models: per-garment accuracy, penetration, build time.

Run (a few seconds, after ``make models`` or with the committed models and a built dataset)::

    python -m benchmarks.explicit_model [--data data/drapes]

- explicit-model error: mean / max distance in mm between the predicted garment (canonical
  prediction + diffused body displacement) and the simulated drape, per vertex, on the
  held-out shapes (never used in training); the training error beside it;
- penetration: the smallest signed distance of any simulated vertex to the body ("min dist",
  positive = outside, negative = inside) and the share of simulated vertices more than 1 mm
  inside the body, against the exact body surface (closest point on its triangles, not the
  simulator's own smoothed distance), over all shapes;
- convergence: share of drapes that met the criterion of training/drape/solve.py within its
  iteration cap, and their mean iterations;
- the dataset's measured build time (data/drapes/build.json);
- for a dataset of real adults (``training.drape.population``), the held-out error by sex and BMI
  band: the people the models never saw; ``--against DIR`` puts beside it that of the explicit models
  in DIR (an earlier tree's, trained on the box) served with the box code they were served with.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks import population
from service.geometry.closest import ClosestPoint
from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.canonical import CanonicalSpace
from service.pipeline.explicit import ExplicitModel
from training.drape.dataset import DEFAULT_DIR, STATS, load_split, split_body_vertices


def vertex_errors(model, space, body, split) -> np.ndarray:
    """Per-vertex distances ``(B, V)`` m between prediction and simulation."""
    bodies = split_body_vertices(body, split)
    pairs = zip(split["beta"], bodies, strict=True)
    pred = np.stack([space.to_body(model.canonical(b), v) for b, v in pairs])
    return np.linalg.norm(pred - split["world"], axis=2)


def penetration(body: BodyModel, splits: list[dict]) -> tuple[float, float]:
    """(deepest vertex depth m (negative = inside), share of vertices > 1 mm inside)."""
    depths = []
    for split in splits:
        for vertices, world in zip(split_body_vertices(body, split), split["world"], strict=True):
            closest = ClosestPoint.build(vertices, body.faces)
            depths.append(closest.query(world.astype(np.float64)).signed)
    d = np.concatenate(depths)
    return float(d.min()), float(np.mean(d < -1e-3))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--data", type=Path, default=DEFAULT_DIR)
    parser.add_argument("--against", type=Path, default=None,
                        help="explicit models of an earlier tree (trained on the box), served with the "
                             "box code (garment_beta): their held-out error beside")  # fmt: skip
    args = parser.parse_args(argv)
    shapes = json.loads((args.data / "shapes.json").read_text())
    record = json.loads((args.data / "build.json").read_text())
    body = BodyModel.load()
    space = CanonicalSpace.build(body.vertices(np.asarray(DEFAULT_BETA)), body.faces)
    # Bodies on disk (an interrupted build trains on those it finished), of the planned ones.
    done = {s: len(list((args.data / s).glob("[0-9][0-9][0-9].npz"))) for s in ("train", "test")}
    planned = {s: len(shapes["betas"][s]) for s in ("train", "test")}
    print(
        f"dataset: {done['train']} training (of {planned['train']} planned) + {done['test']} held-out "
        f"(of {planned['test']}) body shapes x {len(shapes['config']['garments'])} garments"
    )
    print(
        f"build time: {record['seconds'] / 60:.1f} min wall with {record.get('workers', '?')} workers "
        f"({record.get('cpu_seconds', 0) / 60:.1f} min of worker time, {record['bodies']} bodies)\n"
    )
    header = (
        f"{'garment':<12} {'verts':>6} {'PCA':>4} {'test mean':>10} {'test max':>9} {'train mean':>11} "
        f"{'min dist':>8} {'>1mm in':>8} {'converged':>10} {'iters':>6}"
    )
    print(header)
    print("-" * len(header))
    it, conv = STATS.index("iterations"), STATS.index("converged")
    by_band, before = {}, {}
    people = shapes.get("people", {}).get("test")
    for gid in shapes["config"]["garments"]:
        train, test = load_split(args.data, "train", gid), load_split(args.data, "test", gid)
        model = ExplicitModel.load(gid)
        test_err = vertex_errors(model, space, body, test)
        train_err = vertex_errors(model, space, body, train)
        deepest, share = penetration(body, [train, test])
        by_band[gid] = test_err.mean(axis=1)
        if args.against is not None and people:
            boxed = test | {"beta": box_codes(body, people)}
            old = ExplicitModel.load(gid, args.against)
            before[gid] = vertex_errors(old, space, body, boxed).mean(axis=1)
        stats = np.concatenate([train["stats"], test["stats"]])
        print(
            f"{gid:<12} {train['world'].shape[1]:>6} {model.basis.shape[0]:>4} "
            f"{test_err.mean() * 1e3:>7.2f} mm {test_err.max() * 1e3:>6.1f} mm "
            f"{train_err.mean() * 1e3:>8.2f} mm "
            f"{deepest * 1e3:>5.2f} mm {share * 100:>7.3f}% {stats[:, conv].mean() * 100:>9.0f}% "
            f"{stats[:, it].mean():>6.0f}"
        )
    if people:
        band_table(people, by_band, before)


def box_codes(body: BodyModel, people: list) -> np.ndarray:
    """``(B, 3)``: the box code (``garment_beta``) of each ``[sex, row]`` adult's height and weight."""
    from service.pipeline.body_build import BodyRequest, garment_beta

    pops = population.load_all()
    return np.array([garment_beta(body, BodyRequest(population.GENDER[sex], float(pops[sex].height_cm[row]),
                                                    float(pops[sex].weight_kg[row])))
                     for sex, row in people])  # fmt: skip


def band_table(people: list, errors: dict[str, np.ndarray], before: dict[str, np.ndarray]) -> None:
    """Held-out mean vertex error (mm) per sex and BMI band of the test people ``[[sex, row], ...]``,
    each garment's ``errors (B,)`` (m) in their order; ``before``'s beside each where given."""
    pops = population.load_all()
    bmi = np.array([pops[sex].bmi[row] for sex, row in people])
    bands = population.band_index(bmi, population.BMI_EDGES)
    labels = population.band_labels(population.BMI_EDGES)
    title = "mean mm over vertices; people no model saw"
    title += "; before: the --against models" if before else ""
    print(f"\n## Held-out error by sex and BMI band ({title})")
    print("| sex | BMI band | people | BMI | " + " | ".join(errors) + " |")
    print("|---" * (4 + len(errors)) + "|")
    sexes = np.array([sex for sex, _ in people])
    for b, sex in sorted({(int(b), sex) for sex, b in zip(sexes, bands, strict=True)}):
        pick = (sexes == sex) & (bands == b)
        cells = " | ".join(f"{e[pick].mean() * 1e3:.1f}" + (f" (before {before[g][pick].mean() * 1e3:.1f})"
                                                           if g in before else "")
                           for g, e in errors.items())  # fmt: skip
        bmis = ", ".join(f"{x:.0f}" for x in bmi[pick])
        print(f"| {sex} | {labels[b]} | {int(pick.sum())} | {bmis} | {cells} |")


if __name__ == "__main__":
    main()
