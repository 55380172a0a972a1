"""Drapes of each body in the sizes around its own (issue 56): the data the garment models need to
take a size. ``python -m training.drape.sizes [--train N] [--test N] [--garments ids] [--shard K/N]``.

Layout under ``data/drapes_sizes/`` (resumable: finished bodies are skipped, files appear atomically):
``train/000.npz ...``, ``test/...``, one file per body, the same adults as the drapes of real adults
(``training.drape.population``, same split, same order), each draped on the body the service dresses
for them. Per garment, per size of its run (``training.garments.grading.STYLE_RUNS``) within
``SIZE_WINDOW`` letters of the body's own: ``<id>/<size>/world`` and ``<id>/<size>/canonical``
``(V, 3)`` float32 and ``<id>/<size>/stats``, the size's rest shape being the style's pattern on that
size's chart body (``drape_garment(..., rest_body=...)``); and ``beta (3,)``, ``body (B, 3)``.

The body's own letter in a run is the chart row nearest it in the primary girth (chest for tops, hip
for bottoms: ``own_letter``). A size further than ``SIZE_WINDOW`` from it is not draped: a men's XS on
an XXL body is stretched ~50 %, no garment a shopper would be shown, and slow to solve.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from service.pipeline.body import DEFAULT_BETA
from service.pipeline.canonical import CanonicalSpace
from service.pipeline.catalog import load_catalog
from service.pipeline.sizes import LETTERS, chart
from service.process.paths import models_dir
from training.drape.dataset import _save_atomic, drape_garment
from training.drape.solve import DrapeSettings, body_planes
from training.garments.grading import CHARTS_NAME, DEFAULT_RUN, STYLE_RUNS, chart_builder, chart_vertices

DEFAULT_DIR = Path("data/drapes_sizes")
SIZE_WINDOW = 1  # letters either side of the body's own


def own_letter(run: str, bottom: bool, chest_cm: float, hip_cm: float) -> str:
    """The run's letter whose chart row is nearest in the primary girth: hip for a bottom, else chest."""
    rows = chart(run)
    values = np.array([r.hip_cm if bottom else r.chest_cm for r in rows])
    return rows[int(np.argmin(np.abs(values - (hip_cm if bottom else chest_cm))))].letter


def size_window(letter: str) -> tuple[str, ...]:
    """The letters within ``SIZE_WINDOW`` of ``letter``, smallest first."""
    k = LETTERS.index(letter)
    return LETTERS[max(0, k - SIZE_WINDOW) : k + SIZE_WINDOW + 1]


def drape_body_in_sizes(
    builder, garments, space: CanonicalSpace, charts: dict, beta: np.ndarray, body: np.ndarray,
    measured, settings: DrapeSettings,
) -> dict[str, np.ndarray]:  # fmt: skip
    """The arrays of one body's file (module docstring)."""
    faces = builder.model.faces
    planes = body_planes(body, faces)
    arrays = {"beta": np.asarray(beta), "body": body.astype(np.float32)}
    for g in garments:
        run = STYLE_RUNS.get(g.id, DEFAULT_RUN)
        letter = own_letter(run, g.category == "bottom", measured.chest_cm, measured.hip_cm)
        for size in size_window(letter):
            rest = chart_vertices(builder, charts[f"{run}/{size}"])
            d = drape_garment(g, body, faces, space, settings, planes, rest_body=rest)
            arrays[f"{g.id}/{size}/world"] = d.world.astype(np.float32)
            arrays[f"{g.id}/{size}/canonical"] = d.canonical.astype(np.float32)
            arrays[f"{g.id}/{size}/stats"] = np.array([d.iterations, float(d.converged), d.residual,
                                                        d.min_distance, d.seconds, d.last_move])  # fmt: skip
    return arrays


def build(
    out: Path, n_train: int, n_test: int, garment_ids: tuple[str, ...] = (), shard: tuple[int, int] = (0, 1)
) -> dict:
    """Drape every body not yet on disk (the held-out split first); returns the build record. ``shard``
    (k, n): only the bodies whose index is k modulo n, so that n processes share one directory."""
    from training.drape.population import people

    out = Path(out)
    builder = chart_builder()
    catalog = load_catalog()
    garments = [catalog[g] for g in (garment_ids or [g for g, x in catalog.items() if x.origin == "bundled"])]
    space = CanonicalSpace.build(builder.model.vertices(np.asarray(DEFAULT_BETA)), builder.model.faces)
    charts = json.loads((models_dir() / "garments" / CHARTS_NAME).read_text())
    settings = DrapeSettings()
    record_path = out / f"build-{shard[0]}.json"
    record = json.loads(record_path.read_text()) if record_path.exists() else {"seconds": 0.0, "bodies": 0}
    for split, n in (("test", n_test), ("train", n_train)):
        (out / split).mkdir(parents=True, exist_ok=True)
        for i, (person, beta, body) in enumerate(people(n, split) if n else []):
            path = out / split / f"{i:03d}.npz"
            if path.exists() or i % shard[1] != shard[0]:
                continue
            t0 = time.perf_counter()
            measured = builder.build(person.request).measured
            arrays = drape_body_in_sizes(builder, garments, space, charts, beta, body, measured, settings)
            arrays["person"] = np.array([person.sex == "female", person.row])
            _save_atomic(path, arrays)
            record["bodies"] += 1
            record["seconds"] += time.perf_counter() - t0
            record_path.write_text(json.dumps(record, indent=1))
            print(f"{split}/{path.name}: {person.sex} {person.height_cm:.0f} cm {person.weight_kg:.0f} kg "
                  f"in {time.perf_counter() - t0:.0f} s", flush=True)  # fmt: skip
    return record


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--train", type=int, default=40)
    parser.add_argument("--test", type=int, default=6)
    parser.add_argument("--garments", default="", help="comma-separated ids (default: every bundled one)")
    parser.add_argument("--out", type=Path, default=DEFAULT_DIR)
    parser.add_argument("--shard", default="0/1", help="K/N: this process drapes bodies K, K+N, ...")
    args = parser.parse_args(argv)
    k, n = (int(v) for v in args.shard.split("/"))
    garments = tuple(g for g in args.garments.split(",") if g)
    print(json.dumps(build(args.out, args.train, args.test, garments, (k, n))))


if __name__ == "__main__":
    main()
