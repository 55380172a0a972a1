"""The table of bodies a request without girths is served from (``service.pipeline.body_table``).

    python -m training.body_table [--workers 2]

For gender 0 and 1 and every (height, BMI) of the grid ``HEIGHTS_CM x BMIS`` (the served range,
``body_build.HEIGHT_RANGE_CM x BMI_RANGE``), the body ``body_build.build_body`` makes from height and
weight alone: its shape, the girths ``measure`` reads on it and the heights it reads them at. Writes
``models/body/body_table.npz`` (~0.2 MB); a point whose fit fails is NaN (its cells are served by the
full fit), and how much each body crosses itself (``crossings``: the bodies around which the service
looks for crossings to press). Resumable: rows done are kept under ``build/body_table/``. ~2,400 fits,
~20 min on 2 cores.
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from functools import lru_cache

import numpy as np

from service.geometry.self_contact import self_crossings
from service.pipeline.body import BodyModel, ShapeOutOfRange
from service.pipeline.body_build import BMI_RANGE, HEIGHT_RANGE_CM, BodyBuilder, BodyRequest
from service.pipeline.body_table import GIRTH_COLUMNS, LEVEL_COLUMNS, TABLE_NAME
from service.pipeline.girth_priors import GirthPriors
from service.pipeline.measurements import measure
from service.process.paths import REPO_ROOT, models_dir

HEIGHT_STEP_CM = 2.5
BMI_STEP = 1.5
HEIGHTS_CM = np.arange(HEIGHT_RANGE_CM[0], HEIGHT_RANGE_CM[1] + 1e-9, HEIGHT_STEP_CM)
BMIS = np.arange(BMI_RANGE[0], BMI_RANGE[1] + 1e-9, BMI_STEP)
GENDERS = (0.0, 1.0)
CACHE = REPO_ROOT / "build" / "body_table"


@lru_cache(maxsize=1)
def _builder() -> BodyBuilder:
    return BodyBuilder(BodyModel.load(), GirthPriors.load(), press=False)


def row(gender: float, height_cm: float) -> list[list[float]]:
    """Per BMI of ``BMIS``: the shape (S values) then ``GIRTH_COLUMNS``, NaN where the fit fails."""
    out = []
    for bmi in BMIS:
        weight = float(bmi * (height_cm / 100.0) ** 2)
        try:
            built = _builder().build(BodyRequest(gender, float(height_cm), weight))
        except ShapeOutOfRange:
            out.append([float("nan")] * (3 + _builder().model.n_local + len(GIRTH_COLUMNS)))
            continue
        girths = [getattr(built.measured, c) for c in GIRTH_COLUMNS]
        out.append([*built.shape.tolist(), *girths])
    return out


def _job(args) -> tuple[str, list]:
    gender, height = args
    return f"{gender:g}_{height:g}", row(gender, height)


def levels_of(shapes: np.ndarray) -> np.ndarray:
    """``measure``'s tape levels (m, ``LEVEL_COLUMNS``) of each finite shape of ``shapes (..., S)``, NaN
    elsewhere (~25 ms a body)."""
    builder = _builder()
    out = np.full((*shapes.shape[:-1], len(LEVEL_COLUMNS)), np.nan)
    for index in np.ndindex(shapes.shape[:-1]):
        if np.all(np.isfinite(shapes[index])):
            m = measure(builder.model.shape_vertices(shapes[index]), builder.model.faces, builder.marks)
            out[index] = [m.levels_m[c] for c in LEVEL_COLUMNS]
    return out


def crossings_of(shapes: np.ndarray) -> np.ndarray:
    """How many triangle pairs each finite body of ``shapes (..., S)`` crosses itself by, the template's
    toes left out (``self_contact.self_crossings``), 0 elsewhere (~70 ms a body)."""
    model = _builder().model
    out = np.zeros(shapes.shape[:-1], dtype=np.int32)
    for index in np.ndindex(shapes.shape[:-1]):
        if np.all(np.isfinite(shapes[index])):
            vertices = model.shape_vertices(shapes[index])
            out[index] = len(self_crossings(vertices, model.faces, model.template_crossings))
    return out


def build(workers: int) -> dict[str, np.ndarray]:
    CACHE.mkdir(parents=True, exist_ok=True)
    jobs = [(g, float(h)) for g in GENDERS for h in HEIGHTS_CM]
    todo = [j for j in jobs if not (CACHE / f"{j[0]:g}_{j[1]:g}.json").exists()]
    with ProcessPoolExecutor(workers) as pool:
        for key, values in pool.map(_job, todo):
            (CACHE / f"{key}.json").write_text(json.dumps(values))
            print(key, flush=True)
    grid = np.array(
        [[json.loads((CACHE / f"{g:g}_{h:g}.json").read_text()) for h in HEIGHTS_CM] for g in GENDERS]
    )
    n_shape = grid.shape[-1] - len(GIRTH_COLUMNS)
    return {
        "genders": np.array(GENDERS),
        "heights_cm": HEIGHTS_CM,
        "bmis": BMIS,
        "shapes": grid[..., :n_shape],
        "girths_cm": grid[..., n_shape:],
        "girth_columns": np.array(GIRTH_COLUMNS),
        "levels_m": levels_of(grid[..., :n_shape]),
        "level_columns": np.array(LEVEL_COLUMNS),
        "crossings": crossings_of(grid[..., :n_shape]),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    arrays = build(args.workers)
    out = models_dir() / "body" / TABLE_NAME
    np.savez_compressed(out, **arrays)
    corners = arrays["shapes"][..., 0]
    failed = int(np.isnan(corners).sum())
    print(f"wrote {out} ({out.stat().st_size / 1e3:.0f} kB); {failed} of {corners.size} fits failed")


if __name__ == "__main__":
    main()
