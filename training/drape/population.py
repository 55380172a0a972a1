"""Drape bodies drawn from real adults (issue 55): NHANES 2017-2020 (``benchmarks.population``).

The training split draws from the fitting set, the test split from the held-out set, so no test body
and none of the tails ``benchmarks.population --outfits`` dresses is a training body. Each body is the
one the service dresses for that adult asking with their gender, height, weight and hip girth (pressed
where its parts cross, those contacts opened for cloth), and its garment code is
``body_build.garment_code``.

Cells: sex x the BMI bands of ``benchmarks.population`` (7 bands: the tails are as many cells as the
middle, not their ~3 % of adults). People are taken round-robin over the cells in ``CELL_ORDER`` (so
any count spreads over both sexes and far-apart bands first, and a larger count only adds bodies after
the smaller one's: a resumable dataset grows), within a cell at the height quantiles of the split's
``HEIGHT_QUANTILES`` (for training the shortest and the tallest of each cell: the extremes of height
are tails too). An adult the service refuses is replaced by the next one in height.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from benchmarks import population as nhanes
from service.pipeline.body import BodyModel, ShapeOutOfRange
from service.pipeline.body_build import BodyBuilder, BodyRequest, garment_code
from service.pipeline.dressed_body import dressed_vertices
from service.pipeline.girth_priors import GirthPriors

# Band indices (``nhanes.BMI_EDGES``: <18.5, 18.5-25, 25-30, 30-35, 35-40, 40-50, >=50), far apart first.
CELL_ORDER = tuple((band, sex) for band in (2, 5, 0, 6, 3, 1, 4) for sex in nhanes.SEXES)
HEIGHT_QUANTILES = {"train": (0.0, 1.0, 0.5, 0.25, 0.75), "test": (0.5, 0.1, 0.9, 0.3, 0.7)}


@dataclass(frozen=True)
class Person:
    sex: str
    row: int
    height_cm: float
    weight_kg: float
    hip_cm: float

    @property
    def request(self) -> BodyRequest:
        return BodyRequest(nhanes.GENDER[self.sex], self.height_cm, self.weight_kg, hip_cm=self.hip_cm)


def _cell_people(split: str) -> dict[tuple[int, str], list[Person]]:
    """Per cell, the split's adults sorted by height."""
    out = {}
    for sex in nhanes.SEXES:
        fitting, held = nhanes.split(nhanes.load(sex))
        pop = fitting if split == "train" else held
        band = nhanes.band_index(pop.bmi, nhanes.BMI_EDGES)
        for b in range(len(nhanes.BMI_EDGES) + 1):
            idx = np.flatnonzero(band == b)
            idx = idx[np.argsort(pop.height_cm[idx], kind="stable")]
            out[(b, sex)] = [
                Person(sex, int(pop.rows[i]), float(pop.height_cm[i]), float(pop.weight_kg[i]),
                       float(pop.columns["BMXHIP"][i]))
                for i in idx
            ]  # fmt: skip
    return out


@lru_cache(maxsize=1)
def _builder() -> BodyBuilder:
    return BodyBuilder(BodyModel.load(), GirthPriors.load())


def served(person: Person) -> tuple[np.ndarray, np.ndarray] | None:
    """(garment code beta ``(3,)``, body vertices ``(V, 3)``) of ``person``; None if refused. The body
    is the one the service fits garments to: built, pressed where its parts cross and those contacts
    opened for cloth (``dressed_body``)."""
    builder = _builder()
    try:
        built = builder.build(person.request)
    except ShapeOutOfRange:
        return None
    return garment_code(builder.model, builder.marks, person.request), dressed_vertices(builder.model, built)


def people(n: int, split: str) -> list[tuple[Person, np.ndarray, np.ndarray]]:
    """``n`` (person, code ``(3,)``, body ``(V, 3)``) of ``split`` (module docstring)."""
    cells, quantiles = _cell_people(split), HEIGHT_QUANTILES[split]
    out, taken = [], set()
    for round_ in range(len(quantiles)):
        for i, cell in enumerate(CELL_ORDER):
            if len(out) == n:
                return out
            found = _pick(cells[cell], quantiles[_quantile_index(round_, i)], taken)
            if found is not None:
                out.append(found)
                taken.add(found[0].row if found[0].sex == "female" else -1 - found[0].row)
    if len(out) < n:
        raise ValueError(f"only {len(out)} {split} bodies in {len(quantiles)} rounds; asked for {n}")
    return out


def _quantile_index(round_: int, cell: int) -> int:
    """The first two rounds alternate their two quantiles over the cells (by sex, and by band pair):
    a count below two rounds still holds short and tall adults of both sexes."""
    return (round_ + cell // 2 + cell) % 2 if round_ < 2 else round_


def _pick(cell: list[Person], quantile: float, taken: set) -> tuple[Person, np.ndarray, np.ndarray] | None:
    """The adult nearest ``quantile`` of the cell's heights the service serves, not yet taken."""
    if not cell:
        return None
    start = int(round(quantile * (len(cell) - 1)))
    for k in sorted(range(len(cell)), key=lambda i: abs(i - start)):
        p = cell[k]
        if (p.row if p.sex == "female" else -1 - p.row) in taken:
            continue
        done = served(p)
        if done is not None:
            return p, *done
    return None


IN_BETWEEN_SHARE = 0.25
"""Share of ``codes`` whose gender is drawn uniformly in [0, 1] (the API takes any; NHANES has two)."""


def codes(n: int, split: str, seed: int) -> np.ndarray:
    """``(n, 3)`` garment codes of the split's adults, drawn at random within the cells taken
    round-robin (``CELL_ORDER``), without building their bodies: what the fields train and are
    tested on (``training.fields.train``). A share ``IN_BETWEEN_SHARE`` of them take a random
    gender for the adult's height and weight."""
    cells, rng = _cell_people(split), np.random.default_rng(seed)
    builder = _builder()
    out = []
    for i in range(n):
        cell = cells[CELL_ORDER[i % len(CELL_ORDER)]]
        p = cell[int(rng.integers(len(cell)))]
        gender = float(rng.uniform()) if rng.uniform() < IN_BETWEEN_SHARE else nhanes.GENDER[p.sex]
        request = BodyRequest(gender, p.height_cm, p.weight_kg)
        out.append(garment_code(builder.model, builder.marks, request))
    return np.array(out).reshape(-1, 3)
