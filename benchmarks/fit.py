"""Which size each body is recommended, and the ease it has there (issue 56).

Run (~2 min on two cores)::

    python -m benchmarks.fit [--people 8]

Bodies, each asked as the API asks for one:
- **centre**: each chart size's own measurements (``service.pipeline.sizes``: height, chest, waist,
  hip, and the weight its chart body was built at), both runs;
- **between**: halfway between two neighbouring sizes' rows (every measurement, the weight too);
- **people**: held-out NHANES adults (``training.drape.population``'s test split, one per sex and BMI
  band: no fitting of anything saw them), from their height, weight and hip.

For each body and bundled style: the size ``service.pipeline.sizing.recommend`` picks, its runner-up,
and the ease (cm) in every region of that size: its girth (``models/garments/sizes.json``) minus the
tape over the body there. A style's waistband is where its pattern, carried onto the body, puts it.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace

import numpy as np

from service.pipeline.body import DEFAULT_BETA, ShapeOutOfRange
from service.pipeline.body_build import BodyRequest
from service.pipeline.canonical import CanonicalSpace
from service.pipeline.catalog import load_catalog
from service.pipeline.ease import REGIONS, Layer, body_regions, face_parts, girths
from service.pipeline.sizes import LETTERS, RUNS
from service.pipeline.sizing import SIZES_NAME, recommend, region_marks
from service.process.paths import models_dir
from training.garments.grading import CHARTS_NAME, chart_builder

SHORT = {"chest": "chest", "waist": "waist", "waistband": "band", "hip": "hip", "thigh": "thigh",
         "upper_arm": "arm"}  # fmt: skip


def chart_requests(charts: dict) -> list[tuple[str, BodyRequest]]:
    """(label, request) of every chart size's centre and of the halfway bodies between neighbours."""
    out = []
    for run in RUNS:
        requests = [BodyRequest(**charts[f"{run}/{letter}"]["request"]) for letter in LETTERS]
        for letter, r in zip(LETTERS, requests, strict=True):
            out.append((f"{run} {letter} centre", r))
        for k in range(len(LETTERS) - 1):
            (a, ra), (b, rb) = (LETTERS[k], requests[k]), (LETTERS[k + 1], requests[k + 1])
            half = {f: round((getattr(ra, f) + getattr(rb, f)) / 2, 1)
                    for f in ("height_cm", "weight_kg", "chest_cm", "waist_cm", "hip_cm")}  # fmt: skip
            out.append((f"{run} {a}-{b}", replace(ra, **half)))
    return out


def people_requests(n: int) -> list[tuple[str, BodyRequest]]:
    from training.drape.population import people

    out = []
    for person, _, _ in people(n, "test"):
        bmi = person.weight_kg / (person.height_cm / 100) ** 2
        out.append((f"{person.sex} {person.height_cm:.0f} cm BMI {bmi:.0f}", person.request))
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--people", type=int, default=8, help="held-out NHANES adults")
    args = parser.parse_args(argv)
    builder = chart_builder()
    model = builder.model
    charts = json.loads((models_dir() / "garments" / CHARTS_NAME).read_text())
    sizes = json.loads((models_dir() / "garments" / SIZES_NAME).read_text())["styles"]
    catalog = load_catalog()
    space = CanonicalSpace.build(model.vertices(np.asarray(DEFAULT_BETA)), model.faces)
    marks = region_marks(model, builder.marks)
    parts = {s: face_parts(space.mean_vertices, model.regions, model.region_names,
                           catalog[s].vertices, catalog[s].faces) for s in sizes}  # fmt: skip
    bodies = chart_requests(charts) + people_requests(args.people)
    print(f"## Recommended sizes ({len(bodies)} bodies x {len(sizes)} styles; ease in cm of the size)")
    print("| body | style | size | runner-up | fits | " + " | ".join(SHORT[r] for r in REGIONS) + " |")
    print("|---|---|---|---|---|" + "---:|" * len(REGIONS))
    hits = {"centre": [0, 0], "between": [0, 0]}
    for label, request in bodies:
        try:
            built = builder.build(request)
        except ShapeOutOfRange as e:
            print(f"| {label} | refused: {e} |")
            continue
        body = body_regions(built.vertices, model.faces, built.measured.levels_m, marks)
        for style, entry in sizes.items():
            g = catalog[style]
            carried = space.to_body(g.vertices, built.vertices)
            layer = Layer(carried, g.faces, parts[style], g.openings.get("waist"))
            under = {r: u for r, (_, u, _) in girths(body, layer).items()}
            eases = {s: {r: entry["girths"][s][r] - under[r] for r in entry["girths"][s] if r in under}
                     for s in LETTERS}  # fmt: skip
            got = recommend(eases, entry["design_ease"])
            cells = [f"{eases[got.size][r]:+.1f}" if r in eases[got.size] else "" for r in REGIONS]
            runner = f"{got.runner_up} ({got.runner_up_is})" if got.runner_up else ""
            print(f"| {label} | {style} | {got.size} | {runner} | {'yes' if got.fits else 'no'} | "
                  + " | ".join(cells) + " |")  # fmt: skip
            run, *rest = label.split()
            if run == entry["run"] and rest[-1] == "centre":
                hits["centre"][0] += got.size == rest[0]
                hits["centre"][1] += 1
            elif run == entry["run"] and "-" in rest[0]:
                hits["between"][0] += got.size in rest[0].split("-")
                hits["between"][1] += 1
    print()
    print("| bodies of the style's own run | recommended as expected |")
    print("|---|---:|")
    print(f"| at a size's centre: that size | {hits['centre'][0]} of {hits['centre'][1]} |")
    print(f"| between two sizes: one of them | {hits['between'][0]} of {hits['between'][1]} |")


if __name__ == "__main__":
    main()
