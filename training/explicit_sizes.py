"""Train the size models (``service.pipeline.size_model``) from the size drapes (``training.drape.sizes``).

    python -m training.explicit_sizes [--data data/drapes_sizes] [--out models/explicit] [--select] [ids...]

Per garment: every training body's drape in each of its sizes, as the explicit model's body-offset
coordinates q_s, less the explicit model's own prediction q_f for that body (the one-size garment),
against delta = log(size cut / one-size cut) of the primary girth and of the height
(``service.pipeline.size_model``). The model is the size's mean effect: per vertex, the least-squares
fields B_girth, B_height ``(V, 3)`` of q_s - q_f = delta_girth B_girth + delta_height B_height over all
rows, smoothed over the mesh ((I + lambda L) B, L the graph Laplacian, ``SMOOTHING``), which keeps the
size's systematic change (roomier, longer) and leaves out the folds each drape buckles into, which no
size predicts. Measured (``--select``, 4-fold over the training bodies, docs/fit.md): networks of beta
and delta (a tanh MLP, or linear in beta) over the rows' PCA fitted the training rows but were further
from held-out drapes than the one-size garment; the mean effect is the only model that was not.
Held-out bodies (``test/``) are reported, not trained on.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

from service.geometry.mesh import graph_laplacian
from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.catalog import load_catalog
from service.pipeline.explicit import ExplicitModel
from service.pipeline.measurements import landmarks, measure, measure_shape
from service.pipeline.size_model import SizeModel, size_delta
from service.pipeline.sizes import LETTERS
from service.process.paths import models_dir
from training.drape.sizes import DEFAULT_DIR
from training.drape.solve import DrapeSettings
from training.garments.grading import CHARTS_NAME, DEFAULT_RUN, STYLE_RUNS

SMOOTHING = 10.0
"""lambda of the fields' smoothing, in the uniform graph Laplacian's units (vertex steps squared): the
4-fold error over 10 training bodies was 14.4 / 16.4 / 30.8 / 27.1 mm (T-shirt, pants, jacket, skirt) at
10, against 15.0 / 17.9 / 31.5 / 27.8 unsmoothed and 14.1 / 15.8 / 31.6 / 27.4 at 100 (``--select``)."""
SELECT_SMOOTHING = (0.0, 10.0, 100.0)
SHRINKAGE = (0.0, 0.25, 0.5, 0.75, 1.0)
"""The share of the mean effect each garment keeps, the one of these with the least 4-fold error over the
training bodies (0: its sizes are the one-size garment's shape, cut in the size). Where the drapes of a
size differ from the one-size garment mostly by folds no size predicts (the pants), the full effect was
further from held-out drapes than none."""


@dataclass
class SizeRows:
    """One garment's rows over a split: beta (N, 3), delta (N, 2), q_s - q_f (N, V, 3), the drapes'
    canonical vertices (N, V, 3), and per row the body file and size."""

    beta: np.ndarray
    delta: np.ndarray
    offset: np.ndarray
    canonical: np.ndarray
    labels: list[str]


def primary_of(garment) -> str:
    return "hip" if garment.category == "bottom" else "chest"


def size_rows(
    data: Path, split: str, garment, explicit: ExplicitModel, mean_cm: np.ndarray,
    sizes: dict[str, np.ndarray],
) -> SizeRows:
    """The rows of ``garment`` in ``data/split`` (module docstring); ``mean_cm (2,)``: the mean body's
    primary girth and height; ``sizes``: ``chart_sizes``."""
    model = BodyModel.load()
    marks = landmarks(model)
    primary, grading = primary_of(garment), DrapeSettings().grading
    beta, delta, offset, canonical, labels = [], [], [], [], []
    for path in sorted((Path(data) / split).glob("[0-9][0-9][0-9].npz")):
        with np.load(path) as z:
            measured = measure(z["body"].astype(np.float64), model.faces, marks)
            wearer = np.array([getattr(measured, f"{primary}_cm"), measured.height_cm])
            q_f = explicit.encode(explicit.canonical(z["beta"]))
            keys = [k for k in z.files if k.startswith(f"{garment.id}/") and k.endswith("/canonical")]
            for key in sorted(keys):
                size = key.split("/")[1]
                beta.append(z["beta"])
                delta.append(size_delta(sizes[size], wearer, mean_cm, grading))
                offset.append(explicit.encode(z[key].astype(np.float64)) - q_f)
                canonical.append(z[key].astype(np.float64))
                labels.append(f"{split}/{path.stem}/{size}")
    if not beta:
        raise FileNotFoundError(f"no size drapes of {garment.id} in {Path(data) / split}")
    return SizeRows(np.stack(beta), np.stack(delta), np.stack(offset), np.stack(canonical), labels)


def mean_effect(rows: SizeRows, faces: np.ndarray, smoothing: float = SMOOTHING) -> np.ndarray:
    """``(2, V, 3)``: B_girth, B_height (module docstring) of ``rows``, smoothed."""
    N, V, _ = rows.offset.shape
    fields = np.linalg.lstsq(rows.delta, rows.offset.reshape(N, -1), rcond=None)[0].reshape(2, V, 3)
    if smoothing:
        solve = spl.factorized((sp.identity(V) + smoothing * graph_laplacian(faces, V)).tocsc())
        fields = np.stack([np.column_stack([solve(f[:, k]) for k in range(3)]) for f in fields])
    return fields


def fit_size_model(
    garment, rows: SizeRows, mean_cm: np.ndarray, sizes: dict[str, np.ndarray], explicit: ExplicitModel,
    smoothing: float = SMOOTHING, shrinkage: float = 1.0,
) -> SizeModel:  # fmt: skip
    """``garment``'s size model from ``rows`` (module docstring): ``shrinkage`` times the mean effect as
    the basis, and the network that weighs it by delta alone (no hidden layer, no weights: coefficients =
    delta)."""
    basis = (shrinkage * mean_effect(rows, np.asarray(garment.faces), smoothing)).astype(np.float16)
    return SizeModel(
        garment.id, tuple(sizes), STYLE_RUNS.get(garment.id, DEFAULT_RUN), np.stack(list(sizes.values())),
        primary_of(garment), np.asarray(mean_cm, dtype=np.float64), DrapeSettings().grading, basis,
        np.zeros(5), np.ones(5), [np.zeros((4, 5), np.float32)], [np.array([1, 0, 0, 1], np.float32)],
        explicit,
    )  # fmt: skip


def chart_sizes(garment, charts: dict) -> dict[str, np.ndarray]:
    """Each size of the garment's run and its chart body's primary girth and height ``(2,)`` (cm),
    smallest first."""
    run = STYLE_RUNS.get(garment.id, DEFAULT_RUN)
    bodies = {letter: charts[f"{run}/{letter}"]["body"] for letter in LETTERS}
    primary = f"{primary_of(garment)}_cm"
    return {letter: np.array([b[primary], b["height_cm"]]) for letter, b in bodies.items()}


def mean_cut(garment) -> np.ndarray:
    """The mean body's primary girth and height ``(2,)`` (cm): the template's own cut."""
    mean = measure_shape(BodyModel.load(), np.asarray(DEFAULT_BETA))
    return np.array([getattr(mean, f"{primary_of(garment)}_cm"), mean.height_cm])


def errors_mm(model: SizeModel, explicit: ExplicitModel, rows: SizeRows) -> tuple[np.ndarray, np.ndarray]:
    """Per row, mean vertex error (mm) of the size model and of the one-size garment (delta ignored)."""
    sized, one = [], []
    for b, dl, c in zip(rows.beta, rows.delta, rows.canonical, strict=True):
        follow = explicit.canonical(b)
        sized.append(np.linalg.norm(model.canonical(follow, b, dl) - c, axis=1).mean() * 1e3)
        one.append(np.linalg.norm(follow - c, axis=1).mean() * 1e3)
    return np.array(sized), np.array(one)


def rows_of(rows: SizeRows, keep: np.ndarray) -> SizeRows:
    return SizeRows(rows.beta[keep], rows.delta[keep], rows.offset[keep], rows.canonical[keep],
                    [x for x, k in zip(rows.labels, keep, strict=True) if k])  # fmt: skip


def cross_validated_mm(
    garment, rows: SizeRows, mean_cm, sizes, explicit, smoothing: float = SMOOTHING, folds: int = 4
) -> tuple[np.ndarray, float]:  # fmt: skip
    """Mean held-out vertex error (mm) at each ``SHRINKAGE`` of the mean effect, over ``folds`` folds of
    the training bodies (a body's sizes stay together); and the one-size garment's (shrinkage 0)."""
    bodies = np.array(["/".join(x.split("/")[:2]) for x in rows.labels])
    names = sorted(set(bodies))
    errors = []
    for f in range(folds):
        held = np.isin(bodies, names[f::folds])
        model = fit_size_model(garment, rows_of(rows, ~held), mean_cm, sizes, explicit, smoothing)
        for beta, delta, drape in zip(rows.beta[held], rows.delta[held], rows.canonical[held], strict=True):
            q_f = explicit.encode(explicit.canonical(beta))
            offset = model.offset(beta, delta)
            errors.append([np.linalg.norm(explicit.decode(q_f + a * offset) - drape, axis=1).mean() * 1e3
                           for a in SHRINKAGE])  # fmt: skip
    errors = np.array(errors).mean(axis=0)
    return errors, float(errors[SHRINKAGE.index(0.0)])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("ids", nargs="*")
    parser.add_argument("--data", type=Path, default=DEFAULT_DIR)
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--select", action="store_true",
                        help="print the 4-fold error at each SELECT_SMOOTHING and SHRINKAGE; train nothing")
    args = parser.parse_args(argv)
    out = args.out or models_dir() / "explicit"
    catalog = load_catalog()
    charts = json.loads((models_dir() / "garments" / CHARTS_NAME).read_text())
    ids = args.ids or [g for g, x in catalog.items() if x.origin == "bundled"]
    for gid in ids:
        garment, explicit = catalog[gid], ExplicitModel.load(gid, out)
        mean_cm, sizes = mean_cut(garment), chart_sizes(garment, charts)
        train = size_rows(args.data, "train", garment, explicit, mean_cm, sizes)
        if args.select:
            for smoothing in SELECT_SMOOTHING:
                errors, one = cross_validated_mm(garment, train, mean_cm, sizes, explicit, smoothing)
                print(f"| {gid} | {smoothing:g} | {' | '.join(f'{e:.2f}' for e in errors)} |", flush=True)
            continue
        errors, one = cross_validated_mm(garment, train, mean_cm, sizes, explicit)
        shrinkage = SHRINKAGE[int(np.argmin(errors))]
        model = fit_size_model(garment, train, mean_cm, sizes, explicit, shrinkage=shrinkage)
        path = model.save(out / f"{gid}.size.npz")
        line = (f"{gid}: {len(train.delta)} rows; 4-fold {errors.min():.2f} mm (one size {one:.2f}) at "
                f"shrinkage {shrinkage:g}")  # fmt: skip
        for split, rows in (("train", train),):
            sized, one = errors_mm(model, explicit, rows)
            line += f"; {split} {sized.mean():.2f} mm (one size {one.mean():.2f})"
        try:
            test = size_rows(args.data, "test", garment, explicit, mean_cm, sizes)
            sized, one = errors_mm(model, explicit, test)
            line += f"; held out {sized.mean():.2f} mm (one size {one.mean():.2f})"
        except FileNotFoundError:
            line += "; no held-out drapes"
        print(f"{line} -> {path}", flush=True)


if __name__ == "__main__":
    main()
