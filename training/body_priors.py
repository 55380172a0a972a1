"""Girths a shopper did not give: the population's typical value given what she did give (issue 55).

Fits, per sex, log-linear least squares ``log girth = c . (1, log height, log weight, log given...)`` on
the fitting sets of two real surveys, and writes ``models/body/girth_priors.json`` (read by
``service.pipeline.girth_priors``)::

    python -m training.body_priors

| predicts | from | survey (fitting set) |
|---|---|---|
| hip | height, weight (+ chest) | NHANES 2017-2020 (ANSUR II with chest) |
| NHANES waist (iliac crest) | height, weight (+ hip) | NHANES 2017-2020 |
| chest / bust | height, weight (+ hip) | ANSUR II 2012 |
| waist at the navel (range check of a given waist only) | height, weight | ANSUR II 2012 |

Each model keeps its residual standard deviation (log units), the largest |residual| / sd seen in its
fitting set (``z_max``: a given girth further out than ``RANGE_MARGIN`` times that is a body no adult
of either survey has) and its errors on the survey's held-out set. No survey measures the natural
waist of size charts; a missing one is left to the body fitted to the rest (see docs/body.md).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks import ansur, population
from service.process.paths import models_dir

# (target, predictors beyond height and weight, survey, column of the target, columns of the predictors)
MODELS = (
    ("hip_cm", (), "nhanes", "BMXHIP", ()),
    ("hip_cm", ("chest_cm",), "ansur", "BMXHIP", ("chest_cm",)),
    ("waist_iliac_cm", (), "nhanes", "BMXWAIST", ()),
    ("waist_iliac_cm", ("hip_cm",), "nhanes", "BMXWAIST", ("BMXHIP",)),
    ("chest_cm", (), "ansur", "chest_cm", ()),
    ("chest_cm", ("hip_cm",), "ansur", "chest_cm", ("BMXHIP",)),
    ("waist_navel_cm", (), "ansur", "waist_omphalion_cm", ()),
)
SOURCES = {
    "nhanes": "NHANES 2017-March 2020 (CDC, public domain), benchmarks/data/nhanes",
    "ansur": "ANSUR II 2012 (US Army, public domain), benchmarks/data/ansur",
}
OUT = models_dir() / "body" / "girth_priors.json"


def features(height_cm: np.ndarray, weight_kg: np.ndarray, others: list[np.ndarray]) -> np.ndarray:
    """Design matrix ``(N, 3 + len(others))``: 1, log height, log weight, log of each other girth."""
    cols = [np.ones_like(height_cm), np.log(height_cm), np.log(weight_kg), *[np.log(o) for o in others]]
    return np.stack(cols, axis=1)


def _surveys(sex: str) -> dict[str, tuple[population.Population, population.Population]]:
    return {"nhanes": population.split(population.load(sex)), "ansur": ansur.load_split(sex)}


def fit_model(fitting: population.Population, held: population.Population, column: str, predictors) -> dict:
    """Coefficients, residual sd and held-out errors of one model (``MODELS`` row)."""

    def design(p):
        return features(p.height_cm, p.weight_kg, [p.columns[c] for c in predictors])

    x, y = design(fitting), np.log(fitting.columns[column])
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    residual = y - x @ coef
    sd = float(residual.std(ddof=x.shape[1]))
    error = np.exp(design(held) @ coef) - held.columns[column]  # cm
    return {
        "coef": coef.tolist(),
        "sd": sd,
        "z_max": float(np.abs(residual).max() / sd),
        "fitting_n": len(fitting),
        "held_out": {
            "n": len(held),
            "bias_cm": float(np.median(error)),
            "mae_cm": float(np.abs(error).mean()),
            "p90_cm": float(np.percentile(np.abs(error), 90)),
        },
    }


def fit_all() -> dict:
    out = {"sources": SOURCES, "models": {}}
    for sex in population.SEXES:
        surveys = _surveys(sex)
        for target, given, survey, column, predictors in MODELS:
            key = "|".join((sex, target, *given))
            out["models"][key] = {"survey": survey, "given": list(given)} | fit_model(
                *surveys[survey], column, predictors
            )
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    priors = fit_all()
    args.out.write_text(json.dumps(priors, indent=1, sort_keys=True) + "\n")
    print(f"wrote {args.out}")
    print("| model | survey | fitting n | sd (log) | z max | held-out n | bias cm | MAE cm | p90 cm |")
    print("|---|---|---|---|---|---|---|---|---|")
    for key, m in priors["models"].items():
        h = m["held_out"]
        print(
            f"| {key} | {m['survey']} | {m['fitting_n']} | {m['sd']:.3f} | {m['z_max']:.1f} | {h['n']} | "
            f"{h['bias_cm']:+.1f} | {h['mae_cm']:.1f} | {h['p90_cm']:.1f} |"
        )


if __name__ == "__main__":
    main()
