"""The table of bodies served to requests without girths (``service.pipeline.body_table``) against the
fit it was made from (``body_build.build_body`` without a table) and against ``measure`` on the mesh."""

from __future__ import annotations

import numpy as np
import pytest

from service.geometry.self_contact import self_crossings
from service.pipeline.body import BodyModel, body_measurements
from service.pipeline.body_build import PRESSED_WEIGHT_SHARE, BodyRequest, build_body
from service.pipeline.body_table import GIRTH_AGREEMENT_CM, TABLE_NAME, BodyTable
from service.pipeline.girth_priors import GirthPriors
from service.pipeline.measurements import landmarks, measure
from service.process.paths import models_dir

GIRTHS = ("chest_cm", "waist_cm", "hip_cm", "waist_iliac_cm")


@pytest.fixture(scope="module")
def parts():
    model = BodyModel.load()
    return model, landmarks(model), GirthPriors.load(), BodyTable.load(models_dir() / "body" / TABLE_NAME)


def _requests(n: int, seed: int) -> list[BodyRequest]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        height = rng.uniform(142.0, 205.0)
        bmi = rng.uniform(16.0, 55.0)
        gender = float(rng.choice([0.0, 1.0, rng.uniform(0.0, 1.0)]))  # the sexes, and any in between
        out.append(BodyRequest(gender, height, bmi * (height / 100.0) ** 2))
    return out


@pytest.mark.parametrize("request_", _requests(10, seed=4))
def test_a_table_body_has_the_asked_height_and_weight_and_its_girths(parts, request_):
    """Exact height and weight on the mesh (a pressed one: within PRESSED_WEIGHT_SHARE), nothing
    crossing; the girths the report gives within GIRTH_AGREEMENT_CM of ``measure`` on the mesh served."""
    model, marks, priors, table = parts
    built = build_body(model, marks, priors, request_, table)
    assert built.fit is None  # read from the table
    vertices = built.vertices
    height_m, mass_kg = body_measurements(vertices, model.faces)
    slack = 1e-3 if built.pressed is None else PRESSED_WEIGHT_SHARE * request_.weight_kg
    assert abs(100.0 * height_m - request_.height_cm) < 1e-3 and abs(mass_kg - request_.weight_kg) <= slack
    assert len(self_crossings(vertices, model.faces, model.template_crossings)) == 0
    tape = measure(vertices, model.faces, marks)
    for name in GIRTHS:
        assert abs(getattr(built.measured, name) - getattr(tape, name)) <= GIRTH_AGREEMENT_CM, name


def test_between_grid_points_the_table_is_near_the_fit(parts):
    """The reference: the same request fitted (no table) builds a body whose girths are close to the
    table's (both bodies meet the same soft predictions; the fit's ridge leaves the rest near Anny's)."""
    model, marks, priors, table = parts
    for request_ in _requests(4, seed=9):
        fast = build_body(model, marks, priors, request_, table)
        fitted = build_body(model, marks, priors, request_)
        for name in GIRTHS:
            assert abs(getattr(fast.measured, name) - getattr(fitted.measured, name)) < 2.0, name


def test_lookup_outside_the_grid_or_in_a_failed_cell_is_none(parts):
    _, _, _, table = parts
    assert table.lookup(1.0, table.heights_cm[0] - 1.0, 60.0) is None
    assert table.lookup(1.0, 170.0, (table.bmis[-1] + 1.0) * 1.7**2) is None
    shapes = table.shapes.copy()
    shapes[1, 10, 10, 0] = np.nan
    broken = BodyTable(table.genders, table.heights_cm, table.bmis, shapes, table.girths_cm, table.levels_m,
                       table.crossings)
    h = (table.heights_cm[10] + table.heights_cm[11]) / 2
    b = (table.bmis[10] + table.bmis[11]) / 2
    assert broken.lookup(1.0, h, b * (h / 100) ** 2) is None
    assert table.lookup(1.0, h, b * (h / 100) ** 2) is not None


def test_a_body_between_table_bodies_that_do_not_cross_does_not_cross(parts):
    """The table's ``crossings`` decide where the service looks for crossings at all: a body read from
    a cell whose corners do not cross must not cross either (checked on cells next to ones that do)."""
    model, marks, priors, table = parts
    rng = np.random.default_rng(3)
    flagged = table.crossings > 0
    # cells with no crossing corner but a crossing neighbour cell: the edge of where pressing begins
    checked = 0
    for g in range(len(table.genders)):
        edge = [(i, j) for i in range(len(table.heights_cm) - 1) for j in range(1, len(table.bmis) - 2)
                if not flagged[g, i : i + 2, j : j + 2].any() and flagged[g, i : i + 2, j + 2].any()]
        for k in rng.choice(len(edge), size=min(3, len(edge)), replace=False):
            i, j = edge[k]
            h = float(np.mean(table.heights_cm[i : i + 2]))
            b = float(np.mean(table.bmis[j : j + 2]))
            gender = float(table.genders[g])
            shape, _, may_cross = table.lookup(gender, h, b * (h / 100) ** 2)
            assert not may_cross
            built = build_body(model, marks, priors, BodyRequest(gender, h, b * (h / 100) ** 2), table)
            assert len(self_crossings(built.vertices, model.faces, model.template_crossings)) == 0
            checked += 1
    assert checked >= 2
