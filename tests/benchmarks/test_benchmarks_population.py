"""benchmarks.population: the NHANES adults load, split, band and count as its tables say."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks import population as pop
from service.pipeline.body import BodyModel, ShapeOutOfRange
from service.pipeline.body_build import BodyBuilder, BodyRequest
from service.pipeline.girth_priors import GirthPriors
from service.pipeline.measurements import landmarks, measure

SUBSET = 12  # first rows of each sex the counting tests ask the service about (~0.3 s each)


@pytest.fixture(scope="module")
def builder():
    return BodyBuilder(BodyModel.load(), GirthPriors.load())


@pytest.fixture(scope="module")
def everyone():
    return pop.load_all()


@pytest.fixture(scope="module")
def subset(everyone):
    return {sex: p.subset(np.arange(SUBSET)) for sex, p in everyone.items()}


@pytest.fixture(scope="module")
def recs(subset):
    return {sex: pop.records(p, workers=1, cache_dir=None) for sex, p in subset.items()}


@pytest.fixture(scope="module")
def found(recs):
    return {sex: pop.outcomes_of(r) for sex, r in recs.items()}


def cells(rows: list[list[str]]) -> list[list[str]]:
    return [[c.strip() for c in row] for row in rows]


def test_the_files_load_whole_with_their_columns(everyone):
    assert {sex: len(p) for sex, p in everyone.items()} == {"female": 2954, "male": 2856}  # the files' notes
    for p in everyone.values():
        assert set(p.columns) == set(pop.COLUMNS)
        assert np.array_equal(p.rows, np.arange(len(p)))
        for values in p.columns.values():
            assert values.shape == (len(p),) and np.isfinite(values).all() and (values > 0).all()
        assert 120 < p.height_cm.min() and p.height_cm.max() < 210 and 30 < p.weight_kg.min()
    assert everyone["male"].height_cm.mean() > everyone["female"].height_cm.mean() + 10


def test_the_split_is_deterministic_disjoint_whole_and_about_80_20(everyone):
    for sex, p in everyone.items():
        fit, held = pop.split(p)
        again_fit, again_held = pop.split(pop.load(sex))
        assert np.array_equal(fit.rows, again_fit.rows) and np.array_equal(held.rows, again_held.rows)
        assert not set(fit.rows) & set(held.rows)
        assert np.array_equal(np.sort(np.concatenate([fit.rows, held.rows])), p.rows)
        assert 0.17 < len(held) / len(p) < 0.23
        # a row's set depends on its sex and row number only, not on the rows read with it
        some = p.rows[::-7]
        assert np.array_equal(pop.held_out(sex, some), pop.held_out(sex, p.rows)[some])
        assert np.array_equal(held.columns["BMXWT"], p.weight_kg[np.isin(p.rows, held.rows)])
    assert not np.array_equal(pop.held_out("female", np.arange(100)), pop.held_out("male", np.arange(100)))


def test_every_value_lands_in_exactly_one_band():
    edges = pop.BMI_EDGES
    labels = pop.band_labels(edges)
    assert labels == ["<18.5", "18.5-25", "25-30", "30-35", "35-40", "40-50", ">=50"]
    assert pop.band_labels(pop.HEIGHT_EDGES_CM) == [
        "<150", "150-160", "160-170", "170-180", "180-190", ">=190"
    ]  # fmt: skip
    values = np.array([10.0, 18.4999, 18.5, 24.99, 25.0, 49.9, 50.0, 80.0])
    assert pop.band_index(values, edges).tolist() == [0, 0, 1, 1, 2, 5, 6, 6]  # lower edge inclusive
    for p in pop.load_all().values():
        band = pop.band_index(p.bmi, edges)
        assert ((0 <= band) & (band < len(labels))).all()
        member = np.stack([band == i for i in range(len(labels))])
        assert (member.sum(axis=0) == 1).all()


def test_records_are_a_direct_count_of_the_service(builder, subset, recs, found):
    """Each record is the builder's answer for that adult's height, weight and hip; a served one's
    errors are the built body's own measurements minus the asked ones."""
    marks = landmarks(builder.model)
    for sex, p in subset.items():
        held = pop.held_out(sex, p.rows)
        for i, r in enumerate(recs[sex]):
            h, w, hip = p.height_cm[i], p.weight_kg[i], p.columns["BMXHIP"][i]
            try:
                built = builder.build(BodyRequest(p.gender, h, w, hip_cm=hip))
            except ShapeOutOfRange:
                assert r["outcome"] != "served"
                continue
            assert r["outcome"] == "served"
            tape = measure(built.vertices, builder.model.faces, marks)
            assert r["hip_err_cm"] == pytest.approx(tape.hip_cm - hip, abs=1e-9)
            iliac = tape.waist_iliac_cm - p.columns["BMXWAIST"][i]
            assert r["iliac_err_cm"] == pytest.approx(iliac, abs=1e-9)
            assert r["height_err_cm"] == pytest.approx(tape.height_cm - h, abs=1e-9)
            assert abs(r["hip_err_cm"]) <= 1.0 and abs(r["height_err_cm"]) <= 0.5
            assert abs(r["weight_err_pct"]) <= 1.0
            assert ("hip_pred_err_cm" in r) == bool(held[i])
        shares = pop.outcome_shares(found[sex])
        assert sum(shares.values()) == pytest.approx(1.0)
    for gender, (h, w, hip), outcome in ((1.0, (165.0, 250.0, 150.0), "too heavy"),
                                         (0.0, (120.0, 40.0, 80.0), "height"),
                                         (0.0, (175.0, 70.0, 200.0), "girths")):  # fmt: skip
        row = {"BMXHT": h, "BMXWT": w, "BMXHIP": hip, "BMXWAIST": hip}
        assert pop.person_record(builder, gender, row, False)["outcome"] == outcome


def test_records_resume_from_the_cache(tmp_path, subset):
    p = subset["female"].subset(np.arange(3))
    first = pop.records(p, workers=1, cache_dir=tmp_path)
    (path,) = tmp_path.glob("*/female.json")
    cached = json.loads(path.read_text())
    cached["0"]["outcome"] = "marked"  # a rerun reads the cache instead of building again
    path.write_text(json.dumps(cached))
    again = pop.records(p, workers=1, cache_dir=tmp_path)
    assert again[0]["outcome"] == "marked" and again[1:] == first[1:]


def test_the_band_tables_count_every_adult_once(subset, found, recs):
    for rows, edges, values in (
        (pop.bmi_rows(subset, found), pop.BMI_EDGES, {s: p.bmi for s, p in subset.items()}),
        (pop.height_rows(subset, found), pop.HEIGHT_EDGES_CM, {s: p.height_cm for s, p in subset.items()}),
    ):
        rows = cells(rows)
        assert len(rows) == len(subset) * (len(edges) + 1)
        for sex, p in subset.items():
            mine = [r for r in rows if r[0] == sex]
            assert [r[1] for r in mine] == pop.band_labels(edges)
            assert sum(int(r[2]) for r in mine) == len(p)
            band = pop.band_index(values[sex], edges)
            for i, r in enumerate(mine):
                n = int((band == i).sum())
                assert int(r[2]) == n
                if n == 0:
                    assert r[3:] == ["-"] * len(pop.OUTCOMES)
                    continue
                percents = [float(c.rstrip(" %")) for c in r[3:]]
                assert percents[0] == round(100 * (found[sex][band == i] == "served").sum() / n)
    overview = cells(pop.overview_rows(subset, found))
    assert [r[0] for r in overview] == ["female", "male", "all"]
    errors = cells(pop.error_rows(subset, recs))
    assert all(len(r) == len(pop.ERROR_HEADER) for r in errors)
    assert sum(int(r[2]) for r in errors) == sum(int((f == "served").sum()) for f in found.values())
    predictions = cells(pop.prediction_rows(subset, recs))
    assert all(len(r) == len(pop.PREDICTION_HEADER) for r in predictions)


def test_the_tails_are_held_out_and_disjoint():
    everyone = pop.load_all()
    chosen = pop.tail_people(everyone, 4)
    assert len(chosen) == 12 and len({(s, r) for _, s, r in chosen}) == 12
    for tail, sex, row in chosen:
        assert pop.held_out(sex, np.array([row]))[0]
        p = everyone[sex]
        if tail == "BMI over 40":
            assert p.bmi[row] > 40.0
    shortest = [everyone[s].height_cm[r] for t, s, r in chosen if t == "shortest"]
    held_heights = np.concatenate([p.height_cm[pop.held_out(s, p.rows)] for s, p in everyone.items()])
    # the 4 shortest, or the fifth where a heavy one among them was taken first
    assert max(shortest) <= np.sort(held_heights)[4]
