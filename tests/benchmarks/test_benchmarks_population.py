"""benchmarks.population: the NHANES adults load, split, band and count as its tables say."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import population as pop
from service.pipeline.body import BodyModel, ShapeOutOfRange, shape_from_measurements

SUBSET = 40  # first rows of each sex the counting tests ask the service about


@pytest.fixture(scope="module")
def body():
    return BodyModel.load()


@pytest.fixture(scope="module")
def everyone():
    return pop.load_all()


@pytest.fixture(scope="module")
def subset(everyone):
    return {sex: p.subset(np.arange(SUBSET)) for sex, p in everyone.items()}


@pytest.fixture(scope="module")
def found(body, subset):
    return {sex: pop.outcomes(body, p) for sex, p in subset.items()}


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


def test_shares_are_a_direct_count_of_the_service(body, subset, found):
    for sex, p in subset.items():
        served = [0, 0]
        for h, w in zip(p.height_cm, p.weight_kg, strict=True):
            try:
                shape_from_measurements(body, p.gender, h, w)
                served[0] += 1
            except ShapeOutOfRange:
                served[1] += 1
        shares = pop.outcome_shares(found[sex])
        assert all(0.0 <= s <= 1.0 for s in shares.values())
        assert sum(shares.values()) == pytest.approx(1.0)
        assert shares["served"] == served[0] / len(p)
        assert (found[sex] == "served").sum() == served[0] and (found[sex] != "served").sum() == served[1]
    # the first 40 women and men hold both the served and the too heavy
    every = np.concatenate(list(found.values()))
    assert {"served", "too heavy"} <= set(every) <= set(pop.OUTCOMES)
    assert pop.outcome(body, 1.0, 165.0, 200.0) == "too heavy"
    assert pop.outcome(body, 1.0, 165.0, 20.0) == "too light"
    assert pop.outcome(body, 0.0, 120.0, 40.0) == "height"


def test_the_band_tables_count_every_adult_once(subset, found):
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
                assert all(0 <= x <= 100 for x in percents)
                assert percents[0] == round(100 * (found[sex][band == i] == "served").sum() / n)
    overview = cells(pop.overview_rows(subset, found))
    assert [r[0] for r in overview] == ["female", "male", "all"]
    for r, (sex, p) in zip(overview, subset.items(), strict=False):
        assert int(r[1]) + int(r[2]) == int(r[3]) == len(p)
        assert float(r[4].rstrip(" %")) == pytest.approx(100 * (found[sex] == "served").mean(), abs=0.05)
    assert int(overview[-1][3]) == sum(len(p) for p in subset.values())


def test_built_bodies_have_the_asked_height_and_weight(body, subset, found):
    records = {}
    for sex, p in subset.items():
        sample = pop.sample_served(p, found[sex], 3)
        assert len(sample) == min(3, int((found[sex] == "served").sum()))
        assert np.array_equal(sample.rows, pop.sample_served(p, found[sex], 3).rows)  # seeded
        assert (found[sex][np.isin(p.rows, sample.rows)] == "served").all()
        records[sex] = pop.build_sample(body, sample)
        for r in records[sex]:
            assert r["build_ms"] > 0 and r["height_err_cm"] < 1e-3 and r["mass_err_kg"] < 1e-3
    rows = cells(pop.build_rows(records | {"nobody": []}))
    assert len(rows) == 3 and all(len(r) == len(pop.BUILD_HEADER) for r in rows)
    assert rows[-1] == ["nobody", "0"] + ["-"] * (len(pop.BUILD_HEADER) - 2)


def test_the_benchmark_prints_its_five_tables(capsys):
    pop.main(["--sample", "1"])
    out = capsys.readouterr().out
    titles = [line for line in out.splitlines() if line.startswith("## ")]
    assert len(titles) == 5 and titles[3].startswith("## Built bodies (1 served")
    assert titles[-1].startswith("## Girths of the built bodies")
    rules = [line for line in out.splitlines() if line.startswith("|---|")]
    assert len(rules) == 5
    # Every row has as many cells as its header: no "|" inside a cell.
    for block in out.split("## ")[1:]:
        table = [line for line in block.splitlines() if line.startswith("|")]
        assert len({line.count("|") for line in table}) == 1, table[0]


def test_girth_errors_are_the_tape_on_the_mesh_minus_nhanes():
    from service.pipeline.measurements import landmarks, measure

    body = BodyModel.load()
    people = pop.load("female")
    found = pop.outcomes(body, people.subset(np.arange(30)))
    one = pop.sample_served(people.subset(np.arange(30)), found, 1)
    (record,) = pop.build_sample(body, one)
    vertices = body.vertices(shape_from_measurements(body, one.gender, one.height_cm[0], one.weight_kg[0]))
    tape = measure(vertices, body.faces, landmarks(body))
    assert record["hip_err_cm"] == tape.hip_cm - one.columns["BMXHIP"][0]
    assert record["waist_iliac_err_cm"] == tape.waist_iliac_cm - one.columns["BMXWAIST"][0]
    rows = pop.girth_rows({"female": [record], "nobody": []})
    assert rows[0][:3] == ["female", "1", f"{record['hip_err_cm']:+.1f}"]
    assert len(rows[0]) == len(pop.GIRTH_HEADER)
    assert rows[1] == ["nobody", "0"] + ["-"] * (len(pop.GIRTH_HEADER) - 2)
