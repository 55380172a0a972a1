"""Real bodies: how many measured US adults (NHANES 2017-March 2020) today's service serves, and how well.

Run (~5 s on two cores)::

    python -m benchmarks.population [--sample N]

Data: ``benchmarks/data/nhanes/`` (public domain, source in its README.md), one CSV per sex with the
columns of ``COLUMNS``. Each person is asked for as the API would be: gender 0 (men) or 1 (women), their
standing height (cm) and weight (kg), through ``shape_from_measurements``; a refusal is sorted by the
field the ``ShapeOutOfRange`` names (height, or weight below or above the range at that height).

Fitting and held-out sets. ``held_out`` puts a row in the held-out set when the first 8 bytes of
sha256("<sex>/<row>") (sex ``female`` or ``male``, row the 0-based data row of that sex's CSV), read as
a big-endian integer over 2^64, are below ``HELD_OUT_SHARE`` (0.2): a fixed ~80/20 split that does not
depend on numpy, on the order rows are read in, or on any other row. Code that fits anything to these
bodies (issue 55) fits on the fitting set only and reports on the held-out set.

One function computes each table's rows (``*_rows``); ``print_table`` prints them. A later column
(girth errors, clean outfits, latency) is a new key in ``build_sample``'s records or a new ``*_rows``.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from service.pipeline.body import BodyModel, ShapeOutOfRange, body_measurements, shape_from_measurements
from service.pipeline.measurements import landmarks, measure

DATA_DIR = Path(__file__).resolve().parent / "data" / "nhanes"
FILES = {"female": "nhanes_adult_female_bmx_2020.csv", "male": "nhanes_adult_male_bmx_2020.csv"}
SEXES = ("female", "male")
GENDER = {"female": 1.0, "male": 0.0}  # the API's gender for each NHANES sex
# NHANES body-measure columns (README.md there says how each is measured): kg, then cm.
COLUMNS = ("BMXWT", "BMXHT", "BMXARML", "BMXLEG", "BMXARMC", "BMXHIP", "BMXWAIST")
HELD_OUT_SHARE = 0.2
# Band edges: a value v lands in the band [edge_i, edge_i+1), below the first or at/above the last.
BMI_EDGES = (18.5, 25.0, 30.0, 35.0, 40.0, 50.0)
HEIGHT_EDGES_CM = (150.0, 160.0, 170.0, 180.0, 190.0)
# What happened to a request: served, or the reason it was refused.
OUTCOMES = ("served", "height", "too light", "too heavy")
DEFAULT_SAMPLE = 40
SAMPLE_SEED = 0


@dataclass(frozen=True)
class Population:
    """The adults of one sex: ``rows`` (N,) int (0-based data row in the CSV) and ``columns`` name -> (N,)."""

    sex: str
    rows: np.ndarray
    columns: dict[str, np.ndarray]

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def gender(self) -> float:
        return GENDER[self.sex]

    @property
    def height_cm(self) -> np.ndarray:
        return self.columns["BMXHT"]

    @property
    def weight_kg(self) -> np.ndarray:
        return self.columns["BMXWT"]

    @property
    def bmi(self) -> np.ndarray:
        return self.weight_kg / (self.height_cm / 100.0) ** 2

    def subset(self, keep: np.ndarray) -> Population:
        """The rows selected by a boolean mask or an index array, row numbers kept."""
        return Population(self.sex, self.rows[keep], {k: v[keep] for k, v in self.columns.items()})


def load(sex: str, data_dir: Path = DATA_DIR) -> Population:
    """Every adult of ``sex`` (``female`` or ``male``) in file order; ``#`` lines are the file's notes."""
    with open(data_dir / FILES[sex], newline="") as f:
        reader = csv.reader(line for line in f if not line.startswith("#"))
        header = next(reader)
        values = np.array([[float(x) for x in row] for row in reader if row], dtype=np.float64)
    if tuple(header) != COLUMNS:
        raise ValueError(f"{FILES[sex]}: columns {header}, expected {list(COLUMNS)}")
    return Population(sex, np.arange(len(values)), {name: values[:, i] for i, name in enumerate(COLUMNS)})


def load_all(data_dir: Path = DATA_DIR) -> dict[str, Population]:
    return {sex: load(sex, data_dir) for sex in SEXES}


def held_out(sex: str, rows: np.ndarray) -> np.ndarray:
    """(N,) bool: whether each row of ``sex`` is in the held-out set (see the module's docstring)."""

    def fraction(row: int) -> float:
        digest = hashlib.sha256(f"{sex}/{int(row)}".encode()).digest()
        return int.from_bytes(digest[:8], "big") / 2.0**64

    return np.array([fraction(r) < HELD_OUT_SHARE for r in rows], dtype=bool)


def split(population: Population) -> tuple[Population, Population]:
    """(fitting set, held-out set) of ``population``."""
    mask = held_out(population.sex, population.rows)
    return population.subset(~mask), population.subset(mask)


def band_labels(edges: tuple[float, ...]) -> list[str]:
    """``<e0``, ``e0-e1``, ..., ``>=en`` with the edges printed as short as they are."""

    def fmt(e: float) -> str:
        return f"{e:g}"

    return (
        [f"<{fmt(edges[0])}"]
        + [f"{fmt(a)}-{fmt(b)}" for a, b in zip(edges[:-1], edges[1:], strict=True)]
        + [f">={fmt(edges[-1])}"]
    )


def band_index(values: np.ndarray, edges: tuple[float, ...]) -> np.ndarray:
    """(N,) int in [0, len(edges)]: the band of each value, lower edge inclusive."""
    return np.searchsorted(np.asarray(edges), np.asarray(values, dtype=np.float64), side="right")


def outcome(body: BodyModel, gender: float, height_cm: float, weight_kg: float) -> str:
    """``served``, or why ``shape_from_measurements`` refuses the request (one of ``OUTCOMES``)."""
    try:
        shape_from_measurements(body, gender, height_cm, weight_kg)
    except ShapeOutOfRange as e:
        if e.field == "height_cm":
            return "height"
        if e.field == "weight_kg" and e.allowed is not None:
            return "too light" if weight_kg < e.allowed[0] else "too heavy"
        raise
    return "served"


def outcomes(body: BodyModel, population: Population) -> np.ndarray:
    """(N,) str: ``outcome`` of every adult of the population."""
    return np.array(
        [
            outcome(body, population.gender, h, w)
            for h, w in zip(population.height_cm, population.weight_kg, strict=True)
        ]
    )


def outcome_shares(found: np.ndarray) -> dict[str, float]:
    """Share in [0, 1] of each of ``OUTCOMES`` among ``found`` (NaN when it is empty)."""
    n = len(found)
    return {o: float((found == o).sum()) / n if n else float("nan") for o in OUTCOMES}


def _percent(share: float, decimals: int = 0) -> str:
    return "-" if np.isnan(share) else f"{100.0 * share:.{decimals}f} %"


def _outcome_cells(found: np.ndarray, decimals: int = 0) -> list[str]:
    """Adults, then the share served and the shares refused by each reason (percent)."""
    return [str(len(found)), *(_percent(s, decimals) for s in outcome_shares(found).values())]


OUTCOME_HEADER = ["adults", "served", "refused: height", "refused: too light", "refused: too heavy"]


def overview_rows(populations: dict[str, Population], found: dict[str, np.ndarray]) -> list[list[str]]:
    """Per sex, then all together: adults, the fitting / held-out sizes, the shares served and refused
    by reason, and the BMI range of those served."""
    rows = []
    for sex, pop in populations.items():
        n_held = int(held_out(sex, pop.rows).sum())
        bmi = pop.bmi[found[sex] == "served"]
        served_bmi = f"{bmi.min():.1f}-{bmi.max():.1f}" if len(bmi) else "-"
        rows.append([sex, str(len(pop) - n_held), str(n_held), *_outcome_cells(found[sex], 1), served_bmi])
    if len(populations) > 1:
        every = np.concatenate(list(found.values()))
        fit = sum(int(r[1]) for r in rows)
        rows.append(["all", str(fit), str(len(every) - fit), *_outcome_cells(every, 1), "-"])
    return rows


OVERVIEW_HEADER = ["sex", "fitting set", "held-out set", *OUTCOME_HEADER, "BMI served"]


def band_rows(
    populations: dict[str, Population],
    found: dict[str, np.ndarray],
    values: dict[str, np.ndarray],
    edges: tuple[float, ...],
) -> list[list[str]]:
    """Per sex and band of ``values[sex]`` (every band printed, empty ones too): the outcome cells."""
    labels = band_labels(edges)
    rows = []
    for sex in populations:
        band = band_index(values[sex], edges)
        rows += [[sex, label, *_outcome_cells(found[sex][band == i])] for i, label in enumerate(labels)]
    return rows


def bmi_rows(populations: dict[str, Population], found: dict[str, np.ndarray]) -> list[list[str]]:
    return band_rows(populations, found, {s: p.bmi for s, p in populations.items()}, BMI_EDGES)


def height_rows(populations: dict[str, Population], found: dict[str, np.ndarray]) -> list[list[str]]:
    return band_rows(populations, found, {s: p.height_cm for s, p in populations.items()}, HEIGHT_EDGES_CM)


def sample_served(population: Population, found: np.ndarray, n: int, seed: int = SAMPLE_SEED) -> Population:
    """Up to ``n`` served adults drawn without replacement (fixed seed), in row order."""
    served = np.flatnonzero(found == "served")
    pick = np.random.default_rng(seed).choice(served, size=min(n, len(served)), replace=False)
    return population.subset(np.sort(pick))


def build_sample(body: BodyModel, population: Population) -> list[dict[str, float]]:
    """One record per adult: the time to build the body (calibration + rest mesh, ms), the height
    (cm) and mass (kg) errors measured on the built mesh (``body_measurements``) against NHANES', and
    the signed errors (cm, mesh minus NHANES) of the hip girth and of the waist at the iliac crest as a
    tape reads them on the mesh (``service.pipeline.measurements``): girths the body does not take
    today, so these are what its defaults predict for them."""
    marks = landmarks(body)
    records = []
    girths = zip(population.columns["BMXHIP"], population.columns["BMXWAIST"], strict=True)
    for h, w, (hip, waist) in zip(population.height_cm, population.weight_kg, girths, strict=True):
        start = time.perf_counter()
        beta = shape_from_measurements(body, population.gender, h, w)
        vertices = body.vertices(beta)
        ms = 1e3 * (time.perf_counter() - start)
        height_m, mass_kg = body_measurements(vertices, body.faces)
        tape = measure(vertices, body.faces, marks)
        records.append(
            {"build_ms": ms, "height_err_cm": abs(100.0 * height_m - h), "mass_err_kg": abs(mass_kg - w),
             "hip_err_cm": tape.hip_cm - hip, "waist_iliac_err_cm": tape.waist_iliac_cm - waist}
        )  # fmt: skip
    return records


BUILD_HEADER = [
    "sex",
    "bodies",
    "build ms, median",
    "build ms, max",
    "abs height error cm, median",
    "height error, max",
    "abs weight error kg, median",
    "weight error, max",
]


def build_rows(records: dict[str, list[dict[str, float]]]) -> list[list[str]]:
    """Per sex: the sample's size, build time and height / weight errors (median, max)."""
    rows = []
    for sex, recs in records.items():
        if not recs:
            rows.append([sex, "0"] + ["-"] * (len(BUILD_HEADER) - 2))
            continue
        ms, dh, dm = (np.array([r[k] for r in recs]) for k in ("build_ms", "height_err_cm", "mass_err_kg"))
        rows.append(
            [sex, str(len(recs)), f"{np.median(ms):.2f}", f"{ms.max():.2f}"]
            + [f"{np.median(dh):.1e}", f"{dh.max():.1e}", f"{np.median(dm):.1e}", f"{dm.max():.1e}"]
        )
    return rows


GIRTH_HEADER = [
    "sex",
    "bodies",
    "hip error cm, median",
    "abs hip error, median",
    "abs hip error, p90",
    "iliac waist error cm, median",
    "abs iliac waist error, median",
    "abs iliac waist error, p90",
]


def girth_rows(records: dict[str, list[dict[str, float]]]) -> list[list[str]]:
    """Per sex: the built bodies' hip and iliac-waist girths against NHANES' (signed median, and the
    median and 90th percentile of the absolute error, cm)."""
    rows = []
    for sex, recs in records.items():
        if not recs:
            rows.append([sex, "0"] + ["-"] * (len(GIRTH_HEADER) - 2))
            continue
        cells = [sex, str(len(recs))]
        for key in ("hip_err_cm", "waist_iliac_err_cm"):
            e = np.array([r[key] for r in recs])
            size = np.abs(e)
            cells += [f"{np.median(e):+.1f}", f"{np.median(size):.1f}", f"{np.percentile(size, 90):.1f}"]
        rows.append(cells)
    return rows


def print_table(title: str, header: list[str], rows: list[list[str]]) -> None:
    print(f"## {title}")
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows:
        print("| " + " | ".join(row) + " |")
    print()


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sample", type=int, default=DEFAULT_SAMPLE, help="served adults built per sex")
    args = parser.parse_args(argv)
    body = BodyModel.load()
    populations = load_all()
    found = {sex: outcomes(body, pop) for sex, pop in populations.items()}
    print_table(
        "NHANES adults (2017-March 2020) served today", OVERVIEW_HEADER, overview_rows(populations, found)
    )
    print_table("By BMI band (kg/m^2)", ["sex", "BMI", *OUTCOME_HEADER], bmi_rows(populations, found))
    print_table("By height band (cm)", ["sex", "height cm", *OUTCOME_HEADER], height_rows(populations, found))
    records = {
        sex: build_sample(body, sample_served(pop, found[sex], args.sample))
        for sex, pop in populations.items()
    }
    print_table(
        f"Built bodies ({args.sample} served adults per sex, seed {SAMPLE_SEED})",
        BUILD_HEADER,
        build_rows(records),
    )
    print_table(
        "Girths of the built bodies against NHANES' (the service takes no girth today)",
        GIRTH_HEADER,
        girth_rows(records),
    )


if __name__ == "__main__":
    main()
