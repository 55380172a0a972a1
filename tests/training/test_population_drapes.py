"""The garment code of a shopper's body (``body_build.garment_code``) and the real adults the drape
dataset and the fields are drawn from (``training.drape.population``)."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import population as nhanes
from service.pipeline.body import (
    SHAPE_BOUNDS,
    BodyModel,
    body_measurements,
    shape_from_measurements,
    supported_weight_range_kg,
)
from service.pipeline.body_build import BodyRequest, garment_beta, garment_code
from service.pipeline.measurements import landmarks
from training.drape import population


@pytest.fixture(scope="module")
def model_marks():
    model = BodyModel.load()
    return model, landmarks(model)


def _height_weight(model: BodyModel, code: np.ndarray) -> tuple[float, float]:
    shape = np.concatenate([code, np.zeros(model.n_local)])
    height_m, mass = body_measurements(model.shape_vertices(shape), model.faces)
    return 100.0 * height_m, mass


def test_the_code_is_the_box_body_inside_the_box_and_its_extrapolation_beyond(model_marks):
    model, marks = model_marks
    inside = BodyRequest(1.0, 165.0, 60.0)
    np.testing.assert_array_equal(
        garment_code(model, marks, inside), shape_from_measurements(model, 1.0, 165.0, 60.0)
    )
    beyond = (BodyRequest(1.0, 160.0, 130.0), BodyRequest(0.0, 180.0, 160.0), BodyRequest(0.0, 205.0, 60.0))
    for request in beyond:
        code = garment_code(model, marks, request)
        assert not np.array_equal(code, garment_beta(model, request)), "beyond the box"
        height, weight = _height_weight(model, code)
        assert abs(height - request.height_cm) < 0.01 and abs(weight - request.weight_kg) < 0.01


def test_the_code_is_continuous_across_the_box_edge(model_marks):
    model, marks = model_marks
    edge = supported_weight_range_kg(model, 1.0, 160.0)[1]
    below = garment_code(model, marks, BodyRequest(1.0, 160.0, edge - 0.01))
    above = garment_code(model, marks, BodyRequest(1.0, 160.0, edge + 0.01))
    assert np.abs(above - below).max() < 1e-3 and above[2] > 1.0 >= below[2]


def test_a_weight_past_the_extended_phenotype_takes_its_bound_at_the_height(model_marks):
    model, marks = model_marks
    code = garment_code(model, marks, BodyRequest(1.0, 150.0, 145.0))  # BMI 64
    assert code[2] == SHAPE_BOUNDS[2][1]
    assert abs(_height_weight(model, code)[0] - 150.0) < 0.01


def _fake_served(person):
    return np.array([nhanes.GENDER[person.sex], person.height_cm, person.weight_kg]), np.zeros((1, 3))


def test_training_people_are_fitting_adults_spread_over_every_cell(monkeypatch):
    monkeypatch.setattr(population, "served", _fake_served)
    picked = population.people(28, "train")
    rows = [(p.sex, p.row) for p, _, _ in picked]
    assert len(set(rows)) == 28
    for sex in nhanes.SEXES:
        mine = np.array([r for s, r in rows if s == sex])
        assert not nhanes.held_out(sex, mine).any(), "no held-out adult trains"
    # Each cell (sex x BMI band) twice: its shortest and its tallest fitting adult.
    cells = population._cell_people("train")
    for cell, people in cells.items():
        got = sorted(p.height_cm for p, _, _ in picked if (p.sex, p.row) in {(q.sex, q.row) for q in people})
        assert got == [people[0].height_cm, people[-1].height_cm], cell
    # Any prefix count is a prefix of the larger one (a dataset grows resumably), and the first 14
    # already hold short and tall adults of both sexes.
    first = population.people(14, "train")
    assert [(p.sex, p.row) for p, _, _ in first] == rows[:14]
    for sex in nhanes.SEXES:
        heights = [p.height_cm for p, _, _ in first if p.sex == sex]
        assert max(heights) - min(heights) > 20.0, sex


def test_test_people_are_held_out_and_refused_ones_are_replaced(monkeypatch):
    refused = set()

    def served(person):
        if len(refused) < 3 and person.row not in refused:
            refused.add(person.row)
            return None
        return _fake_served(person)

    monkeypatch.setattr(population, "served", served)
    picked = population.people(8, "test")
    assert len(picked) == 8 and not {p.row for p, _, _ in picked} & refused
    for p, _, _ in picked:
        assert nhanes.held_out(p.sex, np.array([p.row]))[0]


def test_field_codes_are_real_adults_codes_with_some_genders_in_between(model_marks):
    codes = population.codes(40, "train", seed=3)
    np.testing.assert_array_equal(codes, population.codes(40, "train", seed=3))
    between = (codes[:, 0] > 0.0) & (codes[:, 0] < 1.0)
    assert 0 < between.sum() < 20
    assert codes[:, 2].max() > 1.5 and codes[:, 2].min() < 0.3, "the BMI tails are beyond the box"
