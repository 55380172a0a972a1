"""Real bodies: how the service serves measured US adults (NHANES 2017-March 2020) from their height,
weight and hip girth, and how well (issue 55).

Run (the held-out sets, ~5 min on two cores the first time; ``--all`` every adult, ~25 min; results
are kept under ``build/population/`` and a rerun of the same models and code reads them)::

    python -m benchmarks.population [--all] [--outfits N]

Data: ``benchmarks/data/nhanes/`` (public domain, source in its README.md), one CSV per sex with the
columns of ``COLUMNS``. Each person asks as the API would: gender 0 (men) or 1 (women), their
standing height (cm), weight (kg) and hip girth (cm), through the service's ``BodyBuilder``; a refusal
is sorted by the field the ``ShapeOutOfRange`` names. A served adult's given measurements are measured
again on the built mesh (``service.pipeline.measurements``); the held-out adults are also built from
height and weight alone, and their body's hip (predicted) and NHANES waist at the iliac crest (never
given) are compared with the real ones. ``--outfits N`` dresses N held-out adults of each tail (the
heaviest over BMI 40, the shortest, the tallest) and reports clean outfits and times.

Fitting and held-out sets. ``held_out`` puts a row in the held-out set when the first 8 bytes of
sha256("<sex>/<row>") (sex ``female`` or ``male``, row the 0-based data row of that sex's CSV), read as
a big-endian integer over 2^64, are below ``HELD_OUT_SHARE`` (0.2): a fixed ~80/20 split that does not
depend on numpy, on the order rows are read in, or on any other row. Code that fits anything to these
bodies (the girth priors, ``training.body_priors``) fits on the fitting set only and is reported on
the held-out set.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from service.pipeline.body import BodyModel, ShapeOutOfRange
from service.pipeline.body_build import BodyBuilder, BodyRequest
from service.pipeline.girth_priors import GirthPriors
from service.process.paths import REPO_ROOT, models_dir

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
OUTCOMES = ("served", "height", "too light", "too heavy", "girths")
SAMPLE_SEED = 0
CACHE_DIR = REPO_ROOT / "build" / "population"
CHUNK = 25  # adults per job of a worker process (and per cache write)
CACHE_INPUTS = (
    models_dir() / "body" / "anny_shape.npz",
    models_dir() / "body" / "girth_priors.json",
    *(
        REPO_ROOT / "service" / "pipeline" / f
        for f in ("body.py", "body_fit.py", "body_build.py", "measurements.py")
    ),  # fmt: skip
    REPO_ROOT / "service" / "geometry" / "girth.py",
    REPO_ROOT / "service" / "geometry" / "self_contact.py",
)


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


def held_out(sex: str, rows: np.ndarray, survey: str = "") -> np.ndarray:
    """(N,) bool: whether each row of ``sex`` is in the held-out set (see the module's docstring);
    another survey's rows hash as ``"<survey>/<sex>/<row>"``."""
    prefix = f"{survey}/" if survey else ""

    def fraction(row: int) -> float:
        digest = hashlib.sha256(f"{prefix}{sex}/{int(row)}".encode()).digest()
        return int.from_bytes(digest[:8], "big") / 2.0**64

    return np.array([fraction(r) < HELD_OUT_SHARE for r in rows], dtype=bool)


def split(population: Population, survey: str = "") -> tuple[Population, Population]:
    """(fitting set, held-out set) of ``population`` (``survey`` as in ``held_out``)."""
    mask = held_out(population.sex, population.rows, survey)
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


def _refusal(error: ShapeOutOfRange, weight_kg: float) -> str:
    if error.field == "weight_kg" and error.allowed is not None:
        return "too light" if weight_kg < error.allowed[0] else "too heavy"
    return {"height_cm": "height"}.get(error.field, "girths")


def person_record(builder: BodyBuilder, gender: float, row: dict[str, float], predict: bool) -> dict:
    """What the service does for one adult asking with their height, weight and hip girth:
    ``outcome`` (one of ``OUTCOMES``) and, when served, the build time (ms), the signed errors of the
    given measurements on the built mesh (height and hip cm, weight %), and the body's NHANES waist
    (iliac crest) against the real one: a girth the shopper did not give. With ``predict``, also
    the hip of the body built from height and weight alone against the real hip."""
    h, w, hip = row["BMXHT"], row["BMXWT"], row["BMXHIP"]
    start = time.perf_counter()
    try:
        built = builder.build(BodyRequest(gender, h, w, hip_cm=hip))
    except ShapeOutOfRange as e:
        return {"outcome": _refusal(e, w)}
    m = built.measured
    record = {"outcome": "served", "build_ms": 1e3 * (time.perf_counter() - start),
              "height_err_cm": m.height_cm - h, "weight_err_pct": 100.0 * (m.weight_kg - w) / w,
              "hip_err_cm": m.hip_cm - hip, "iliac_err_cm": m.waist_iliac_cm - row["BMXWAIST"],
              "pressed": built.pressed is not None,
              "crossings": built.pressed.crossings if built.pressed is not None else 0}  # fmt: skip
    if predict:
        try:
            alone = builder.build(BodyRequest(gender, h, w))
            record["hip_pred_err_cm"] = alone.measured.hip_cm - hip
        except ShapeOutOfRange:
            record["hip_pred_err_cm"] = float("nan")
    return record


def cache_key() -> str:
    """sha256 (12 hex) of what a record depends on: the body model, the priors and the code that builds."""
    digest = hashlib.sha256()
    for path in CACHE_INPUTS:
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def _records_chunk(args) -> list[tuple[int, dict]]:
    sex, rows, predict = args
    builder = _builder()
    people = load(sex).subset(np.array(rows))
    out = []
    for i, r in enumerate(people.rows):
        row = {c: float(people.columns[c][i]) for c in COLUMNS}
        out.append((int(r), person_record(builder, people.gender, row, bool(predict[i]))))
    return out


@lru_cache(maxsize=1)
def _builder() -> BodyBuilder:
    return BodyBuilder(BodyModel.load(), GirthPriors.load())


def records(population: Population, workers: int = 2, cache_dir: Path | None = CACHE_DIR) -> list[dict]:
    """``person_record`` of every adult of ``population`` (in its order; held-out adults with
    ``predict``), computed on ``workers`` processes and kept under ``cache_dir/<cache_key>/`` (a rerun
    reads them; an interrupted run resumes)."""
    path = None if cache_dir is None else cache_dir / cache_key() / f"{population.sex}.json"
    done: dict[int, dict] = {}
    if path is not None and path.exists():
        done = {int(k): v for k, v in json.loads(path.read_text()).items()}
    held = held_out(population.sex, population.rows)
    todo = [(int(r), bool(h)) for r, h in zip(population.rows, held, strict=True) if int(r) not in done]
    chunks = [todo[i : i + CHUNK] for i in range(0, len(todo), CHUNK)]
    jobs = [(population.sex, [r for r, _ in c], [p for _, p in c]) for c in chunks]
    if jobs:
        with ProcessPoolExecutor(workers) if workers > 1 else _Serial() as pool:
            for result in pool.map(_records_chunk, jobs):
                done |= dict(result)
                if path is not None:
                    path.parent.mkdir(parents=True, exist_ok=True)
                    path.write_text(json.dumps(done))
    return [done[int(r)] for r in population.rows]


class _Serial:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def map(self, fn, jobs):
        return map(fn, jobs)


def outcomes_of(recs: list[dict]) -> np.ndarray:
    """(N,) str: each record's outcome."""
    return np.array([r["outcome"] for r in recs])


def outcome_shares(found: np.ndarray) -> dict[str, float]:
    """Share in [0, 1] of each of ``OUTCOMES`` among ``found`` (NaN when it is empty)."""
    n = len(found)
    return {o: float((found == o).sum()) / n if n else float("nan") for o in OUTCOMES}


def _percent(share: float, decimals: int = 0) -> str:
    return "-" if np.isnan(share) else f"{100.0 * share:.{decimals}f} %"


def _outcome_cells(found: np.ndarray, decimals: int = 0) -> list[str]:
    """Adults, then the share served and the shares refused by each reason (percent)."""
    return [str(len(found)), *(_percent(s, decimals) for s in outcome_shares(found).values())]


OUTCOME_HEADER = [
    "adults",
    "served",
    "refused: height",
    "refused: too light",
    "refused: too heavy",
    "refused: girths",
]


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


def _stats(values: np.ndarray, kind: str) -> str:
    """``median / max`` of |values| (kind "abs"), or signed median / MAE / p90 (kind "signed")."""
    v = values[np.isfinite(values)]
    if not len(v):
        return "-"
    if kind == "abs":
        return f"{np.median(np.abs(v)):.2f} / {np.abs(v).max():.2f}"
    return f"{np.median(v):+.1f} / {np.abs(v).mean():.1f} / {np.percentile(np.abs(v), 90):.1f}"


ERROR_HEADER = ["sex", "BMI", "served", "height error cm", "weight error %", "hip error cm", "pressed",
                "crossing after", "build ms", "build ms, max"]  # fmt: skip


def error_rows(populations: dict[str, Population], recs: dict[str, list[dict]]) -> list[list[str]]:
    """Per sex and BMI band: the served, the given measurements' errors on the built mesh (|error|
    median / max), how many bodies were pressed where their parts crossed and how many still cross
    (``self_contact``), and the build time (median, max)."""
    rows = []
    for sex, pop in populations.items():
        band = band_index(pop.bmi, BMI_EDGES)
        for i, label in enumerate(band_labels(BMI_EDGES)):
            served = [r for r, b in zip(recs[sex], band, strict=True) if b == i and r["outcome"] == "served"]
            keys = ("height_err_cm", "weight_err_pct", "hip_err_cm", "build_ms")
            col = {k: np.array([r[k] for r in served]) for k in keys}
            ms = col["build_ms"]
            rows.append(
                [
                    sex,
                    label,
                    str(len(served)),
                    _stats(col["height_err_cm"], "abs"),
                    _stats(col["weight_err_pct"], "abs"),
                    _stats(col["hip_err_cm"], "abs"),
                    str(sum(r.get("pressed", False) for r in served)),
                    str(sum(r.get("crossings", 0) > 0 for r in served)),
                    f"{np.median(ms):.0f}" if len(ms) else "-",
                    f"{ms.max():.0f}" if len(ms) else "-",
                ]
            )
    return rows


PREDICTION_HEADER = ["sex", "BMI", "held-out served", "hip from height and weight: bias / MAE / p90 cm",
                     "NHANES waist given the hip: bias / MAE / p90 cm"]  # fmt: skip


def prediction_rows(populations: dict[str, Population], recs: dict[str, list[dict]]) -> list[list[str]]:
    """Per sex and BMI band, held-out adults only: the body's girths the shopper did not give against
    the real ones (signed median, mean |error|, 90th percentile of |error|, cm)."""
    rows = []
    for sex, pop in populations.items():
        band = band_index(pop.bmi, BMI_EDGES)
        held = held_out(sex, pop.rows)
        for i, label in enumerate([*band_labels(BMI_EDGES), "all"]):
            pick = [r for r, b, h in zip(recs[sex], band, held, strict=True)
                    if h and (b == i or label == "all") and "hip_pred_err_cm" in r]  # fmt: skip
            rows.append([sex, label, str(len(pick)),
                         _stats(np.array([r["hip_pred_err_cm"] for r in pick]), "signed"),
                         _stats(np.array([r["iliac_err_cm"] for r in pick]), "signed")])  # fmt: skip
    return rows


def print_table(title: str, header: list[str], rows: list[list[str]]) -> None:
    print(f"## {title}")
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows:
        print("| " + " | ".join(row) + " |")
    print()


# Outfits of 2-4 garments tried on the tails, in turn (the benchmarks.outfits ones plus a skirt).
TAIL_OUTFITS = (
    ("tshirt", "jacket"),
    ("pants", "tshirt", "jacket"),
    ("tank_top", "tshirt", "long_sleeve", "jacket"),
    ("shorts", "tank_top"),
    ("skirt", "tshirt", "jacket"),
)
TAILS = ("BMI over 40", "shortest", "tallest")


def tail_people(populations: dict[str, Population], per_tail: int) -> list[tuple[str, str, int]]:
    """(tail, sex, row) of ``per_tail`` held-out adults per tail, both sexes together: the highest BMIs
    over 40, the shortest, the tallest (each adult at most once)."""
    held = {sex: p.subset(held_out(sex, p.rows)) for sex, p in populations.items()}
    every = [(sex, int(r), float(p.bmi[i]), float(p.height_cm[i])) for sex, p in held.items()
             for i, r in enumerate(p.rows)]  # fmt: skip
    keys = {"BMI over 40": lambda e: -e[2], "shortest": lambda e: e[3], "tallest": lambda e: -e[3]}
    chosen, taken = [], set()
    for tail in TAILS:
        pick = [e for e in sorted(every, key=keys[tail]) if (e[0], e[1]) not in taken]
        pick = [e for e in pick if tail != "BMI over 40" or e[2] > 40.0][:per_tail]
        chosen += [(tail, sex, row) for sex, row, _, _ in pick]
        taken |= {(e[0], e[1]) for e in pick}
    return chosen


def outfit_records(populations: dict[str, Population], per_tail: int) -> list[dict]:
    """Each tail adult (``tail_people``) dressed in the next of ``TAIL_OUTFITS`` by the service's own
    engine: clean by the exact count of crossing pairs between every two layers of the returned meshes
    and of vertices inside an inner layer (the report's ``intersections_after`` and
    ``penetration_after``), what the report's ``collision_free`` said, and the body and
    outfit times (ms, this process, warm caches; the outfit's with those measures)."""
    from service.pipeline.tryon import ModelEngine, OutfitSpec

    engine = ModelEngine.load(models_dir(), threads=2)
    out = []
    for k, (tail, sex, row) in enumerate(tail_people(populations, per_tail)):
        p = populations[sex]
        i = int(np.flatnonzero(p.rows == row)[0])
        garments = TAIL_OUTFITS[k % len(TAIL_OUTFITS)]
        spec = OutfitSpec(garments, p.gender, float(p.height_cm[i]), float(p.weight_kg[i]),
                          hip_cm=float(p.columns["BMXHIP"][i]), measure=True)  # fmt: skip
        start = time.perf_counter()
        engine.body(spec)
        body_ms = 1e3 * (time.perf_counter() - start)
        result = engine.make(spec)
        outfit_ms = 1e3 * (time.perf_counter() - start) - body_ms
        out.append({"tail": tail, "sex": sex, "bmi": float(p.bmi[i]), "height_cm": float(p.height_cm[i]),
                    "garments": len(garments), "said_clean": bool(result.report.get("collision_free")),
                    "clean": sum(result.report["intersections_after"].values()) == 0
                    and sum(result.report["penetration_after"].values()) == 0,
                    "body_ms": body_ms, "outfit_ms": outfit_ms})  # fmt: skip
    return out


OUTFIT_HEADER = ["tail", "adults", "BMI", "height cm", "garments", "clean (exact)", "report said clean",
                 "body ms, median", "outfit ms, median", "outfit ms, max"]  # fmt: skip


def outfit_rows(recs: list[dict]) -> list[list[str]]:
    rows = []
    for tail in TAILS:
        rs = [r for r in recs if r["tail"] == tail]
        if not rs:
            continue
        keys = ("bmi", "height_cm", "garments", "body_ms", "outfit_ms")
        col = {k: np.array([r[k] for r in rs]) for k in keys}
        rows.append([tail, str(len(rs)), f"{col['bmi'].min():.0f}-{col['bmi'].max():.0f}",
                     f"{col['height_cm'].min():.0f}-{col['height_cm'].max():.0f}",
                     f"{col['garments'].min():.0f}-{col['garments'].max():.0f}",
                     f"{sum(r['clean'] for r in rs)} of {len(rs)}",
                     f"{sum(r.get('said_clean', r['clean']) for r in rs)} of {len(rs)}",
                     f"{np.median(col['body_ms']):.0f}",
                     f"{np.median(col['outfit_ms']):.0f}", f"{col['outfit_ms'].max():.0f}"])  # fmt: skip
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--all", action="store_true", help="every adult (default: the held-out sets)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument(
        "--outfits",
        type=int,
        default=0,
        metavar="N",
        help="also dress N held-out adults of each tail (BMI over 40, shortest, tallest)",
    )
    args = parser.parse_args(argv)
    populations = load_all()
    if not args.all:
        populations = {sex: p.subset(held_out(sex, p.rows)) for sex, p in populations.items()}
    recs = {sex: records(p, args.workers) for sex, p in populations.items()}
    found = {sex: outcomes_of(r) for sex, r in recs.items()}
    who = "every adult" if args.all else "the held-out sets"
    print_table(f"NHANES adults served, given height, weight and hip ({who})", OVERVIEW_HEADER,
                overview_rows(populations, found))  # fmt: skip
    print_table("By BMI band (kg/m^2)", ["sex", "BMI", *OUTCOME_HEADER], bmi_rows(populations, found))
    print_table("By height band (cm)", ["sex", "height cm", *OUTCOME_HEADER], height_rows(populations, found))
    print_table("Given measurements on the built bodies (abs error median / max)", ERROR_HEADER,
                error_rows(populations, recs))  # fmt: skip
    print_table("Girths not given, held-out adults (body minus NHANES)", PREDICTION_HEADER,
                prediction_rows(populations, recs))  # fmt: skip
    if args.outfits:
        print_table(f"Outfits on the tails ({args.outfits} held-out adults each)", OUTFIT_HEADER,
                    outfit_rows(outfit_records(load_all(), args.outfits)))  # fmt: skip


if __name__ == "__main__":
    main()
