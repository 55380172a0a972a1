"""Garments worn in sizes (issue 56): how close the service's sizes are to their drapes, and whether
outfits in sizes come out clean.

Run (a few minutes on two cores, on the size drapes ``python -m training.drape.sizes`` makes)::

    python -m benchmarks.worn_sizes [--data data/drapes_sizes] [--people 8] [--outfits-only | --shapes-only]

1. **Shape**, per garment, on the held-out bodies of the size drapes (``test/``: adults no training
   saw), each in its own letter and one either side: mean vertex distance (mm) of the service's size
   (explicit model + size model, ``service.pipeline.size_model``) to the simulated drape of that size,
   against the one-size garment's (what the service showed before sizes, whatever the size asked);
   the tension map's stretch (``service.pipeline.tension``: smoothed mean principal stretch) of the
   simulated drape and of the service's mesh, median over the vertices, averaged over the rows, and
   the Pearson correlation of the two maps over the vertices; and, unsmoothed, the largest principal
   strain's median of each.
2. **Outfits**: on ``--people`` held-out NHANES adults (``training.drape.population``'s test split, from
   height, weight and hip), each usual outfit of ``benchmarks.outfits`` with every garment in the
   body's own letter (the chart row nearest in chest, or hip for a bottom), one smaller and one larger,
   and as bare ids (the one-size garments): the share clean (``collision_free``), crossing pairs left,
   and the request's ms (one at a time, the body built before).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from benchmarks.outfits import OUTFITS
from service.pipeline.catalog import load_catalog
from service.pipeline.explicit import ExplicitModel
from service.pipeline.size_model import SizeModel
from service.pipeline.sizes import LETTERS
from service.pipeline.tension import CutShapes
from service.pipeline.tryon import ModelEngine, OutfitSpec
from service.process.paths import models_dir
from training.drape.sizes import DEFAULT_DIR, own_letter
from training.explicit_sizes import chart_sizes, mean_cut, size_rows
from training.garments.grading import CHARTS_NAME, DEFAULT_RUN, STYLE_RUNS


def shape_table(data: Path, engine: ModelEngine) -> None:
    catalog = load_catalog()
    charts = json.loads((models_dir() / "garments" / CHARTS_NAME).read_text())
    cuts = CutShapes(engine.models)
    space = engine.models.space
    print(f"`python -m benchmarks.worn_sizes --data {data} --shapes-only`\n")
    print("| garment | rows | size, mm | one size, mm | stretch p50, drape / service | map correlation "
          "| largest strain p50, drape / service |")  # fmt: skip
    print("|---|---:|---:|---:|---:|---:|---:|")
    for gid in [g for g, x in catalog.items() if x.origin == "bundled"]:
        garment, explicit, model = catalog[gid], ExplicitModel.load(gid), SizeModel.load(gid)
        rows = size_rows(data, "test", garment, explicit, mean_cut(garment), chart_sizes(garment, charts))
        sized, one, stretch, correlation, largest = [], [], [], [], []
        files = {}
        for label, beta, delta, canonical in zip(
            rows.labels, rows.beta, rows.delta, rows.canonical, strict=True
        ):
            split, stem, size = label.split("/")
            if stem not in files:
                with np.load(Path(data) / split / f"{stem}.npz") as z:
                    files[stem] = (
                        z["body"].astype(np.float64),
                        {k: z[k] for k in z.files if k.endswith("/world")},
                    )
            body, worlds = files[stem]
            follow = explicit.canonical(beta)
            mine = model.canonical(follow, beta, delta)
            sized.append(np.linalg.norm(mine - canonical, axis=1).mean() * 1e3)
            one.append(np.linalg.norm(follow - canonical, axis=1).mean() * 1e3)
            drape, served = worlds[f"{gid}/{size}/world"], space.to_body(mine, body)
            maps = [cuts.stretch(gid, size, body, x) for x in (drape, served)]
            stretch.append([np.median(m) for m in maps])
            correlation.append(np.corrcoef(*maps)[0, 1])
            largest.append([np.median(cuts.strain(gid, size, body, x)) for x in (drape, served)])
        d, s = 100 * np.mean(stretch, axis=0), 100 * np.mean(largest, axis=0)
        print(f"| {gid} | {len(sized)} | {np.mean(sized):.1f} | {np.mean(one):.1f} "
              f"| {d[0]:.1f} / {d[1]:.1f} % | {np.mean(correlation):.2f} | {s[0]:.1f} / {s[1]:.1f} % |",
              flush=True)  # fmt: skip


def outfit_table(engine: ModelEngine, n_people: int) -> None:
    from training.drape.population import people

    print(f"\n`python -m benchmarks.worn_sizes --people {n_people} --outfits-only`\n")
    print("| sizes | outfits | clean | crossing pairs | ms p50 | ms max |")
    print("|---|---:|---:|---:|---:|---:|")
    catalog = load_catalog()
    results: dict[int | None, list] = {None: [], -1: [], 0: [], 1: []}
    for person, _, _ in people(n_people, "test"):
        measured = engine.body(OutfitSpec(("tshirt",), *_request_values(person.request))).measured
        for outfit in OUTFITS:
            own = []
            for g in outfit:
                run = STYLE_RUNS.get(g, DEFAULT_RUN)
                own.append(LETTERS.index(own_letter(run, catalog[g].category == "bottom", measured.chest_cm,
                                                    measured.hip_cm)))  # fmt: skip
            for step in results:
                sizes = (
                    ()
                    if step is None
                    else tuple(LETTERS[min(max(k + step, 0), len(LETTERS) - 1)] for k in own)
                )
                spec = OutfitSpec(outfit, *_request_values(person.request), sizes=sizes)
                t0 = time.perf_counter()
                report = engine.make(spec).report
                ms = (time.perf_counter() - t0) * 1e3
                results[step].append((report["collision_free"], report.get("crossing_pairs", 0), ms))
    for step, rows in results.items():
        clean = sum(r[0] for r in rows)
        ms = np.array([r[2] for r in rows])
        name = {None: "one size (bare ids)", -1: "one smaller", 0: "own letter", 1: "one larger"}[step]
        print(f"| {name} | {len(rows)} | {clean} | {sum(r[1] for r in rows)} | {np.median(ms):.0f} | "
              f"{ms.max():.0f} |")  # fmt: skip


def _request_values(request) -> tuple:
    return (request.gender, request.height_cm, request.weight_kg, request.chest_cm, request.waist_cm,
            request.hip_cm)  # fmt: skip


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--data", type=Path, default=DEFAULT_DIR)
    parser.add_argument("--people", type=int, default=8)
    parser.add_argument("--outfits-only", action="store_true")
    parser.add_argument("--shapes-only", action="store_true")
    args = parser.parse_args(argv)
    engine = ModelEngine.load(models_dir(), threads=2)
    if not args.outfits_only:
        shape_table(args.data, engine)
    if not args.shapes_only:
        outfit_table(engine, args.people)


if __name__ == "__main__":
    main()
