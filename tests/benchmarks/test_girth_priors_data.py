"""The committed girth priors are what ``training.body_priors`` makes from the survey data, and their
possible ranges hold every measured adult of the held-out sets."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks import ansur, population
from service.pipeline.girth_priors import GirthPriors
from training.body_priors import OUT, fit_all


def test_committed_priors_are_the_data_fit():
    committed = json.loads(OUT.read_text())
    again = fit_all()
    assert committed.keys() == again.keys() and committed["models"].keys() == again["models"].keys()
    for key, model in again["models"].items():
        np.testing.assert_allclose(committed["models"][key]["coef"], model["coef"], rtol=1e-9, err_msg=key)
        assert committed["models"][key]["sd"] == pytest.approx(model["sd"], rel=1e-9)


@pytest.mark.parametrize("sex", population.SEXES)
def test_possible_ranges_hold_every_held_out_adult(sex):
    priors = GirthPriors.load()
    gender = population.GENDER[sex]
    _, nhanes = population.split(population.load(sex))
    _, army = ansur.load_split(sex)
    for people, column, name in ((nhanes, "BMXHIP", "hip_cm"), (army, "BMXHIP", "hip_cm"),
                                 (army, "chest_cm", "chest_cm")):  # fmt: skip
        for h, w, value in zip(people.height_cm, people.weight_kg, people.columns[column], strict=True):
            lo, hi = priors.possible_range(gender, name, h, w)
            assert lo <= value <= hi, (sex, name, h, w, value, lo, hi)
