"""The population's typical girths given a shopper's height, weight and the girths she gave (issue 55).

``models/body/girth_priors.json`` (``python -m training.body_priors``) holds log-linear models per sex,
each fitted on one real survey's fitting set (NHANES 2017-2020 or ANSUR II, both public domain):
``log girth = c . (1, log height_cm, log weight_kg, log given girth...)``. A gender between 0 and 1
mixes the two sexes' predictions in log space. ``predict`` picks, for each missing girth, the model
that uses the most of the given ones (``MODELS`` lists which can be used), and ``possible_range`` is
how far a given girth may lie from its prediction from height and weight alone: ``RANGE_MARGIN`` times
the largest residual either survey's fitting set has.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from service.process.paths import models_dir

# Which given girths each prediction may use (the surveys measured these together).
MODELS = {
    "hip_cm": (("chest_cm",), ()),
    "waist_iliac_cm": (("hip_cm",), ()),
    "chest_cm": (("hip_cm",), ()),
}
# A given waist (natural) is checked against the navel-level waist of ANSUR II, the closest a survey
# measures it; none predicts it (docs/body.md).
RANGE_MODEL = {"chest_cm": "chest_cm", "waist_cm": "waist_navel_cm", "hip_cm": "hip_cm"}
# Beyond anything measured: 1.25 x the largest |residual| / sd of the model's fitting set (3.4-5.6).
RANGE_MARGIN = 1.25
SEXES = {"female": 1.0, "male": 0.0}


@dataclass(frozen=True)
class Prediction:
    """A predicted girth (cm) and the model's residual spread (cm, one standard deviation)."""

    value_cm: float
    sd_cm: float
    model: str  # e.g. "hip_cm|chest_cm": the target and the given girths it used


class GirthPriors:
    """The models of ``girth_priors.json`` (module docstring)."""

    def __init__(self, data: dict):
        self.models = data["models"]
        self.sources = data["sources"]

    @classmethod
    def load(cls, path: Path | str | None = None) -> GirthPriors:
        path = Path(path) if path is not None else models_dir() / "body" / "girth_priors.json"
        return cls(json.loads(Path(path).read_text()))

    def _log_mean(
        self, sex: str, key: str, height_cm: float, weight_kg: float, given: dict
    ) -> tuple[float, float]:
        model = self.models[f"{sex}|{key}"]
        x = [1.0, math.log(height_cm), math.log(weight_kg), *[math.log(given[g]) for g in model["given"]]]
        return sum(c * xi for c, xi in zip(model["coef"], x, strict=True)), model["sd"]

    def _mixed(
        self, gender: float, key: str, height_cm: float, weight_kg: float, given: dict
    ) -> tuple[float, float]:
        """Log mean and sd mixed over the sexes by ``gender`` (1 female, 0 male)."""
        female = self._log_mean("female", key, height_cm, weight_kg, given)
        male = self._log_mean("male", key, height_cm, weight_kg, given)
        mean = gender * female[0] + (1.0 - gender) * male[0]
        return mean, gender * female[1] + (1.0 - gender) * male[1]

    def predict(
        self, gender: float, height_cm: float, weight_kg: float, given: dict[str, float]
    ) -> dict[str, Prediction]:
        """A ``Prediction`` for each girth of ``MODELS`` not in ``given`` (name -> cm)."""
        out = {}
        for target, choices in MODELS.items():
            if target in given:
                continue
            uses = next(c for c in choices if all(g in given for g in c))
            key = "|".join((target, *uses))
            mean, sd = self._mixed(gender, key, height_cm, weight_kg, given)
            out[target] = Prediction(math.exp(mean), math.exp(mean) * sd, key)
        return out

    def possible_range(
        self, gender: float, name: str, height_cm: float, weight_kg: float
    ) -> tuple[float, float]:
        """Girths (cm) of ``name`` (chest_cm, waist_cm or hip_cm) some adult of this height and weight has."""
        key = RANGE_MODEL[name]
        mean, sd = self._mixed(gender, key, height_cm, weight_kg, {})
        z = RANGE_MARGIN * max(self.models[f"{s}|{key}"]["z_max"] for s in SEXES)
        return math.exp(mean - z * sd), math.exp(mean + z * sd)
