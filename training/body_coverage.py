"""Issue 55 study: can Anny, with extrapolated phenotypes and MakeHuman's girth targets, be fitted to
real adults' height, weight, hip and (iliac) waist? Results in
docs/decisions/0020-body-parameters-for-real-adults.md.

Run (resumable: every fit is cached under ``build/body_coverage/``, a rerun only does what is missing)::

    python -m training.body_coverage [--people N] [--sex female|male] [--variant girths]
    python -m training.body_coverage --intersections      # self-intersections of the fitted bodies
    python -m training.body_coverage --pictures           # build/body_coverage/bodies_*.png, docs/images
    python -m training.body_coverage --report             # tables, also in build/body_coverage/report.md

Anny is built with ``extrapolate_phenotypes=True`` (phenotypes may leave [0, 1]; the interpolation
extends linearly past the end anchors) and the local changes of ``LOCAL_CHANGES`` (each one signed
parameter driving MakeHuman's ``-incr`` target when positive and its ``-decr`` one when negative), age and
proportions fixed as the service has them (``training.anny_body.FIXED_PHENOTYPES``), gender 0 (men) or
1 (women). A person is measured on the mesh exactly as the service measures a body:
``service.pipeline.measurements.measure`` (height: z extent; weight: volume x 1010 kg/m^3; hip; NHANES's
iliac waist), with the landmarks of the committed body model (same topology, same vertex order).

The fit (``fit``) is a Levenberg-Marquardt least squares over the variant's free parameters with a
forward-difference Jacobian (all columns in one batched Anny call). Residuals are in units of the
tolerances (``TOLERANCES``: height 0.5 cm, weight 1 %, each girth 1 cm), so "fitted" means every
residual is within [-1, 1]; a small ridge pulls the parameters that the targets do not pin down to their
prior (muscle to the service's 0.25, local changes to 0).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from service.process.paths import REPO_ROOT

OUT_DIR = REPO_ROOT / "build" / "body_coverage"
DOC_IMAGE = REPO_ROOT / "docs" / "images" / "body_coverage.png"
TOPOLOGY = "anny-noeyes-notongue"
AGE = 2.0 / 3.0
PROPORTIONS = 0.5
SERVICE_MUSCLE = 0.25
LOCAL_CHANGES = (
    "measure-waist-circ-incr",
    "measure-hips-circ-incr",
    "stomach-pregnant-incr",
    "measure-bust-circ-incr",
    "measure-thigh-circ-incr",
    "measure-upperarm-circ-incr",
)
SHORT = {
    "measure-waist-circ-incr": "waist",
    "measure-hips-circ-incr": "hips",
    "stomach-pregnant-incr": "belly",
    "measure-bust-circ-incr": "bust",
    "measure-thigh-circ-incr": "thigh",
    "measure-upperarm-circ-incr": "upperarm",
}
# What is measured on every body; the first four are the targets.
QUANTITIES = ("height_cm", "weight_kg", "hip_cm", "waist_iliac_cm", "waist_cm", "chest_cm")
TARGET_COLUMNS = {
    "height_cm": "BMXHT",
    "weight_kg": "BMXWT",
    "hip_cm": "BMXHIP",
    "waist_iliac_cm": "BMXWAIST",
}
TOLERANCES = {"height_cm": 0.5, "weight_kg": 0.01, "hip_cm": 1.0, "waist_iliac_cm": 1.0}  # weight: relative
RELATIVE = {"weight_kg"}


@dataclass(frozen=True)
class Variant:
    """Free parameters (phenotypes or local changes, in Anny units), their bounds, their prior and
    ridge weight (residual units per parameter unit), and which quantities are fitted."""

    params: tuple[str, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    prior: tuple[float, ...]
    ridge: tuple[float, ...]
    targets: tuple[str, ...]


_PHENO_BOUNDS = {"height": (-0.6, 1.6), "weight": (-0.5, 3.0), "muscle": (0.0, 1.0)}
_LOCAL_BOUNDS = (-1.5, 3.0)


def _variant(params: tuple[str, ...], targets: tuple[str, ...]) -> Variant:
    lower = tuple(_PHENO_BOUNDS.get(p, _LOCAL_BOUNDS)[0] for p in params)
    upper = tuple(_PHENO_BOUNDS.get(p, _LOCAL_BOUNDS)[1] for p in params)
    prior = tuple({"height": 0.5, "weight": 0.5, "muscle": SERVICE_MUSCLE}.get(p, 0.0) for p in params)
    ridge = tuple({"height": 1e-3, "weight": 1e-3, "muscle": 2.0}.get(p, 0.5) for p in params)
    return Variant(params, lower, upper, prior, ridge, targets)


HW = ("height_cm", "weight_kg")
FOUR = ("height_cm", "weight_kg", "hip_cm", "waist_iliac_cm")
VARIANTS = {
    # today's parameters, extrapolated: height and weight only, muscle at the service's 0.25
    "hw": _variant(("height", "weight"), HW),
    # + muscle and the waist and hip girth targets, fitted to all four
    "girths": _variant(
        ("height", "weight", "muscle", "measure-waist-circ-incr", "measure-hips-circ-incr"), FOUR
    ),
    # + the bust, thigh and upper-arm girths, which NHANES's four targets see only through the weight
    "limbs": _variant(
        (
            "height",
            "weight",
            "muscle",
            "measure-waist-circ-incr",
            "measure-hips-circ-incr",
            "measure-bust-circ-incr",
            "measure-thigh-circ-incr",
            "measure-upperarm-circ-incr",
        ),
        FOUR,
    ),
    # + the belly ("stomach-pregnant"), which moves the iliac waist below a belly
    "belly": _variant(
        (
            "height",
            "weight",
            "muscle",
            "measure-waist-circ-incr",
            "measure-hips-circ-incr",
            "stomach-pregnant-incr",
        ),
        FOUR,
    ),
}


# ---------------------------------------------------------------- pure fitting


@dataclass(frozen=True)
class FitResult:
    x: np.ndarray  # (P,) parameters
    values: np.ndarray  # (K,) model output at x
    residuals: np.ndarray  # (K,) (values - targets) / scales
    cost: float
    iterations: int
    evaluations: int  # model rows evaluated


def fit(
    forward: Callable[[np.ndarray], np.ndarray],
    targets: np.ndarray,
    scales: np.ndarray,
    x0: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    prior: np.ndarray | None = None,
    ridge: np.ndarray | None = None,
    step: float = 0.01,
    max_iterations: int = 30,
    stop: float = 0.1,
    gradient_stop: float = 1e-2,
) -> FitResult:
    """Box-bounded Levenberg-Marquardt least squares of ``(forward(x) - targets) / scales`` plus the ridge
    ``ridge * (x - prior)``.

    forward: ``(B, P) -> (B, K)`` batched model (NaN rows: the model failed there). targets, scales: (K,).
    x0, lower, upper, prior, ridge: (P,). The Jacobian is by forward differences of ``step`` (backward at
    the upper bound), all P columns and the current point in one batched call. Stops when every data
    residual is below ``stop`` in absolute value and the cost's gradient (J^T r) below ``gradient_stop``
    (so the ridge has settled the parameters the data leave free), when a step no longer lowers the cost
    by a relative 1e-9, or after ``max_iterations`` Jacobians.
    """
    targets, scales = np.asarray(targets, float), np.asarray(scales, float)
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    n = len(x0)
    prior = np.zeros(n) if prior is None else np.asarray(prior, float)
    ridge = np.zeros(n) if ridge is None else np.asarray(ridge, float)
    evaluations = 0

    def residuals(values: np.ndarray, x: np.ndarray) -> np.ndarray:
        return np.concatenate([(values - targets) / scales, ridge * (x - prior)])

    def cost_of(r: np.ndarray) -> float:
        return float(r @ r) if np.all(np.isfinite(r)) else np.inf

    x = np.clip(np.asarray(x0, float), lower, upper)
    mu = 1e-5
    values = None
    it = 0
    for it in range(1, max_iterations + 1):  # noqa: B007 (the count is reported)
        h = np.where(x + step <= upper, step, -step)
        batch = np.vstack([x, x + np.diag(h)])
        out = np.asarray(forward(batch), float)
        evaluations += len(batch)
        values = out[0]
        r = residuals(values, x)
        cost = cost_of(r)
        if not np.isfinite(cost):
            raise ValueError(f"the model fails at the start point {x}")
        jd = (out[1:] - values) / h[:, None] / scales  # (P, K)
        jd = np.where(np.isfinite(jd), jd, 0.0).T  # (K, P)
        jac = np.vstack([jd, np.diag(ridge)])
        jtj, jtr = jac.T @ jac, jac.T @ r
        if np.all(np.abs(r[: len(targets)]) < stop) and np.max(np.abs(jtr)) < gradient_stop:
            break
        improved = False
        for _ in range(12):
            delta = np.linalg.solve(jtj + mu * (np.diag(np.diag(jtj)) + np.eye(n)), -jtr)
            x_new = np.clip(x + delta, lower, upper)
            v_new = np.asarray(forward(x_new[None]), float)[0]
            evaluations += 1
            c_new = cost_of(residuals(v_new, x_new))
            if c_new < cost:
                improved = c_new < cost * (1 - 1e-9)
                x, mu = x_new, max(mu / 10.0, 1e-9)
                break
            mu *= 10.0
        if not improved:
            break
    else:
        values = np.asarray(forward(x[None]), float)[0]
        evaluations += 1
    r = residuals(values, x)
    return FitResult(x, values, r[: len(targets)], cost_of(r), it, evaluations)


def within_tolerance(residuals: np.ndarray) -> bool:
    """Every residual (in tolerance units) within [-1, 1]."""
    return bool(np.all(np.abs(np.asarray(residuals)) <= 1.0))


# ---------------------------------------------------------------- Anny


class AnnyBodies:
    """Anny with extrapolated phenotypes and ``LOCAL_CHANGES``, and the service's measurements."""

    def __init__(self):
        cache = Path(os.environ.get("ULNEF_CACHE_DIR", Path.home() / ".cache" / "ulnef")) / "anny"
        os.environ.setdefault("ANNY_CACHE_DIR", str(cache))
        import anny
        import torch

        from service.pipeline.body import BodyModel
        from service.pipeline.measurements import landmarks

        torch.set_num_threads(1)
        self.torch = torch
        self.model = anny.Anny(
            topology=TOPOLOGY, extrapolate_phenotypes=True, local_changes=list(LOCAL_CHANGES)
        )
        self.model.requires_grad_(False)
        self.faces = self.model.faces.detach().numpy().astype(np.int64)
        self.body = BodyModel.load()
        if not np.array_equal(self.faces, self.body.faces):
            raise ValueError("Anny's faces differ from the committed body model's")
        self.marks = landmarks(self.body)
        self.labels = list(self.model.local_change_labels)

    def vertices(self, gender: float, variant: Variant, x: np.ndarray) -> np.ndarray:
        """Rest vertices ``(B, V, 3)`` for parameters ``x (B, P)`` of ``variant``."""
        torch = self.torch
        x = np.atleast_2d(np.asarray(x, float))
        b = len(x)
        pheno = {"gender": gender, "age": AGE, "proportions": PROPORTIONS, "muscle": SERVICE_MUSCLE}
        kw = {k: torch.full((b,), float(v), dtype=torch.float64) for k, v in pheno.items()}
        local = torch.zeros((b, len(self.labels)), dtype=torch.float64)
        for i, p in enumerate(variant.params):
            col = torch.as_tensor(x[:, i], dtype=torch.float64)
            if p in self.labels:
                local[:, self.labels.index(p)] = col
            else:
                kw[p] = col
        out = self.model(phenotype_kwargs=kw, local_changes_kwargs=local)
        return out["rest_vertices"].detach().numpy()

    def measure(self, vertices: np.ndarray) -> np.ndarray:
        """``QUANTITIES`` of one body ``(V, 3)`` (NaN where the measurement fails)."""
        from service.pipeline.measurements import measure

        try:
            m = measure(vertices, self.faces, self.marks)
        except ValueError:
            return np.full(len(QUANTITIES), np.nan)
        return np.array([getattr(m, q) for q in QUANTITIES])

    def forward(self, gender: float, variant: Variant) -> Callable[[np.ndarray], np.ndarray]:
        idx = [QUANTITIES.index(t) for t in variant.targets]

        def run(x: np.ndarray) -> np.ndarray:
            return np.array([self.measure(v)[idx] for v in self.vertices(gender, variant, x)])

        return run


def start_point(variant: Variant, gender: float, height_cm: float, bmi: float) -> np.ndarray:
    """A rough start: Anny's height axis is ~108.9 cm per unit (women 176.9 cm, men 190.9 cm at 0.5);
    the weight axis ~26 (women) or ~32 (men) BMI per unit above 0.5 at BMI 22 (24)."""
    base, bmi0, per = (176.9, 22.0, 26.0) if gender > 0.5 else (190.9, 24.0, 30.0)
    guess = {"height": 0.5 + (height_cm - base) / 108.9, "weight": 0.5 + (bmi - bmi0) / per}
    x = np.array([guess.get(p, prior) for p, prior in zip(variant.params, variant.prior, strict=True)])
    return np.clip(x, variant.lower, variant.upper)


# ---------------------------------------------------------------- people


def sample_people(sex: str, n: int, seed: int = 0) -> list[dict]:
    """``n`` adults of the FITTING set with all four targets: the highest-BMI n/8, the lowest-BMI, shortest
    and tallest n/15 each, the rest at random. Each: row, sex, and the NHANES columns."""
    from benchmarks.population import load, split

    fitting, _ = split(load(sex))
    ok = np.all([np.isfinite(fitting.columns[c]) for c in TARGET_COLUMNS.values()], axis=0)
    pop = fitting.subset(ok)
    picked: list[int] = []

    def take(order: np.ndarray, k: int) -> None:
        for i in order:
            if k <= 0:
                return
            if i not in picked:
                picked.append(int(i))
                k -= 1

    tail = max(1, n // 15)
    take(np.argsort(-pop.bmi), max(1, n // 8))
    take(np.argsort(pop.bmi), tail)
    take(np.argsort(pop.height_cm), tail)
    take(np.argsort(-pop.height_cm), tail)
    take(np.random.default_rng(seed).permutation(len(pop)), n - len(picked))
    people = []
    for i in picked[:n]:
        person = {"sex": sex, "row": int(pop.rows[i])}
        person.update({q: float(pop.columns[c][i]) for q, c in TARGET_COLUMNS.items()})
        person["bmi"] = person["weight_kg"] / (person["height_cm"] / 100) ** 2
        people.append(person)
    return people


def _path(variant: str, person: dict, suffix: str = "json") -> Path:
    return OUT_DIR / variant / f"{person['sex']}_{person['row']:05d}.{suffix}"


def fit_person(bodies: AnnyBodies, variant_name: str, person: dict) -> dict:
    variant = VARIANTS[variant_name]
    gender = 1.0 if person["sex"] == "female" else 0.0
    targets = np.array([person[t] for t in variant.targets])
    scales = np.array([TOLERANCES[t] * (person[t] if t in RELATIVE else 1.0) for t in variant.targets])
    t0 = time.perf_counter()
    result = fit(
        bodies.forward(gender, variant),
        targets,
        scales,
        start_point(variant, gender, person["height_cm"], person["bmi"]),
        np.array(variant.lower),
        np.array(variant.upper),
        np.array(variant.prior),
        np.array(variant.ridge),
    )
    seconds = time.perf_counter() - t0
    measured = bodies.measure(bodies.vertices(gender, variant, result.x[None])[0])
    residual = {}
    for q in TARGET_COLUMNS:
        d = measured[QUANTITIES.index(q)] - person[q]
        residual[q] = float(100.0 * d / person[q] if q in RELATIVE else d)  # weight in %, others cm
    return {
        "person": person,
        "variant": variant_name,
        "params": dict(zip(variant.params, result.x.tolist(), strict=True)),
        "measured": dict(zip(QUANTITIES, measured.tolist(), strict=True)),
        "residual": residual,  # cm, weight in %
        "fitted": within_tolerance(result.residuals),
        "all_within": bool(
            all(
                abs(residual[q]) <= (100 * TOLERANCES[q] if q in RELATIVE else TOLERANCES[q])
                for q in residual
            )
        ),
        "seconds": seconds,
        "iterations": result.iterations,
        "evaluations": result.evaluations,
    }


def load_results(variant: str) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted((OUT_DIR / variant).glob("*.json"))]


def run_fits(variant: str, sexes: list[str], people: int) -> None:
    bodies = AnnyBodies()
    for sex in sexes:
        for k, person in enumerate(sample_people(sex, people)):
            path = _path(variant, person)
            if path.exists():
                continue
            rec = fit_person(bodies, variant, person)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(rec, indent=1))
            r = rec["residual"]
            print(
                f"{variant} {sex} {k + 1}/{people} row {person['row']} BMI {person['bmi']:.1f} "
                f"H {person['height_cm']:.1f}: dh {r['height_cm']:+.2f} dw {r['weight_kg']:+.2f}% "
                f"dhip {r['hip_cm']:+.2f} dwaist {r['waist_iliac_cm']:+.2f} "
                f"{'fitted' if rec['all_within'] else 'NOT fitted'} {rec['seconds']:.1f} s "
                + " ".join(f"{SHORT.get(p, p)}={v:.2f}" for p, v in rec["params"].items()),
                flush=True,
            )


# ---------------------------------------------------------------- self-intersections


def face_region_pairs(pairs: np.ndarray, faces: np.ndarray, regions: np.ndarray, names) -> dict[str, int]:
    """Counts of intersecting face pairs by the (sorted) body regions of their first vertices, with the
    sides' suffixes kept (``upperleg_l/upperleg_r`` is the thighs overlapping)."""
    counts: dict[str, int] = {}
    for a, b in pairs:
        ra, rb = sorted((names[regions[faces[a, 0]]], names[regions[faces[b, 0]]]))
        key = f"{ra}/{rb}"
        counts[key] = counts.get(key, 0) + 1
    return dict(sorted(counts.items(), key=lambda kv: -kv[1]))


def run_intersections(variant: str, sexes: list[str], only_pictured: bool = False) -> None:
    from service.geometry.intersections import intersecting_pairs

    bodies = AnnyBodies()
    results = load_results(variant)
    if only_pictured:
        results = [r for sex in sexes for r in pictured(results, sex)]
    for rec in results:
        person = rec["person"]
        if person["sex"] not in sexes:
            continue
        path = _path(variant, person, "selfx")
        if path.exists():
            continue
        v = variant_vertices(bodies, rec)
        t0 = time.perf_counter()
        pairs = intersecting_pairs(v, bodies.faces)
        regions = face_region_pairs(pairs, bodies.faces, bodies.body.regions, bodies.body.region_names)
        out = {"pairs": len(pairs), "regions": regions, "seconds": time.perf_counter() - t0}
        path.write_text(json.dumps(out))
        print(
            f"{person['sex']} row {person['row']} BMI {person['bmi']:.1f}: {len(pairs)} {regions}", flush=True
        )


def variant_vertices(bodies: AnnyBodies, rec: dict) -> np.ndarray:
    variant = VARIANTS[rec["variant"]]
    gender = 1.0 if rec["person"]["sex"] == "female" else 0.0
    x = np.array([rec["params"][p] for p in variant.params])
    return bodies.vertices(gender, variant, x[None])[0]


# ---------------------------------------------------------------- report


def _band(bmi: float) -> str:
    from benchmarks.population import BMI_EDGES, band_index, band_labels

    return band_labels(BMI_EDGES)[int(band_index(np.array([bmi]), BMI_EDGES)[0])]


def table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def report_rows(results: list[dict]) -> list[list[str]]:
    """Per sex and BMI band (then per sex): people, share fitted (all four within tolerance), median and
    max |residual| of each target, time per fit."""
    from benchmarks.population import BMI_EDGES, band_labels

    rows = []
    for sex in ("female", "male"):
        mine = [r for r in results if r["person"]["sex"] == sex]
        for band in [*band_labels(BMI_EDGES), "all"]:
            sel = [r for r in mine if band == "all" or _band(r["person"]["bmi"]) == band]
            if not sel:
                continue
            cells = [sex, band, str(len(sel)), f"{100 * np.mean([r['all_within'] for r in sel]):.0f} %"]
            for q in TARGET_COLUMNS:
                a = np.abs([r["residual"][q] for r in sel])
                cells.append(f"{np.median(a):.2f} / {a.max():.2f}")
            cells.append(f"{np.median([r['seconds'] for r in sel]):.1f}")
            rows.append(cells)
    return rows


REPORT_HEADER = [
    "sex",
    "BMI",
    "people",
    "fitted",
    "height cm med/max",
    "weight % med/max",
    "hip cm med/max",
    "iliac waist cm med/max",
    "s per fit (median)",
]


def param_rows(results: list[dict]) -> list[list[str]]:
    rows = []
    for sex in ("female", "male"):
        mine = [r for r in results if r["person"]["sex"] == sex]
        if not mine:
            continue
        for p in mine[0]["params"]:
            x = np.array([r["params"][p] for r in mine])
            rows.append([sex, SHORT.get(p, p), f"{x.min():.2f}", f"{np.median(x):.2f}", f"{x.max():.2f}"])
    return rows


def selfx_rows(variant: str, results: list[dict]) -> list[list[str]]:
    from benchmarks.population import BMI_EDGES, band_labels

    rows = []
    for sex in ("female", "male"):
        for band in [*band_labels(BMI_EDGES), "all"]:
            found = []
            for r in results:
                p = _path(variant, r["person"], "selfx")
                if (
                    r["person"]["sex"] == sex
                    and (band == "all" or _band(r["person"]["bmi"]) == band)
                    and p.exists()
                ):
                    found.append(json.loads(p.read_text()))
            if not found:
                continue
            n = np.array([f["pairs"] for f in found])
            thighs = np.array([f["regions"].get("upperleg_l/upperleg_r", 0) for f in found])
            arms = np.array(
                [sum(c for k, c in f["regions"].items() if "torso" in k and "arm" in k) for f in found]
            )
            rows.append(
                [
                    sex,
                    band,
                    str(len(found)),
                    f"{np.median(n):.0f} / {n.max()}",
                    f"{np.mean(thighs > 0) * 100:.0f} % ({thighs.max()})",
                    f"{np.mean(arms > 0) * 100:.0f} % ({arms.max()})",
                ]
            )
    return rows


SELFX_HEADER = [
    "sex",
    "BMI",
    "bodies",
    "pairs med/max",
    "thighs cross (max pairs)",
    "arm into torso (max pairs)",
]


def run_report(variants: list[str]) -> str:
    parts = []
    for name in variants:
        results = load_results(name)
        if not results:
            continue
        v = VARIANTS[name]
        parts.append(
            f"## variant `{name}`: free {', '.join(SHORT.get(p, p) for p in v.params)}; fitted to "
            f"{', '.join(v.targets)}\n"
        )
        parts.append(table(REPORT_HEADER, report_rows(results)) + "\n")
        parts.append(table(["sex", "parameter", "min", "median", "max"], param_rows(results)) + "\n")
        sx = selfx_rows(name, results)
        if sx:
            parts.append(table(SELFX_HEADER, sx) + "\n")
    text = "\n".join(parts)
    (OUT_DIR / "report.md").write_text(text)
    return text


# ---------------------------------------------------------------- pictures

PICTURE_BMI = (19.0, 25.0, 32.0, 40.0, 47.0, 55.0)


def pictured(results: list[dict], sex: str) -> list[dict]:
    """The fitted people of ``sex`` nearest to each BMI of ``PICTURE_BMI`` (each once), by BMI."""
    mine = [r for r in results if r["person"]["sex"] == sex]
    chosen: list[dict] = []
    for b in PICTURE_BMI:
        rest = [r for r in mine if r not in chosen]
        if rest:
            chosen.append(min(rest, key=lambda r: abs(r["person"]["bmi"] - b)))
    return sorted(chosen, key=lambda r: r["person"]["bmi"])


def run_pictures(variant: str, size: int) -> None:
    from training.render import PALETTE, MeshLayer, grid, render_views, save_png

    bodies = AnnyBodies()
    images, titles = [], []
    for sex in ("female", "male"):
        for rec in pictured(load_results(variant), sex):
            p, m = rec["person"], rec["measured"]
            v = variant_vertices(bodies, rec)
            images.append(
                render_views([MeshLayer(v, bodies.faces, PALETTE["skin"])], ("front", "side"), size)
            )
            titles.append(
                f"{sex} {p['height_cm']:.0f} cm {p['weight_kg']:.0f} kg BMI {p['bmi']:.0f}; "
                f"hip {p['hip_cm']:.0f}/{m['hip_cm']:.0f}, "
                f"waist {p['waist_iliac_cm']:.0f}/{m['waist_iliac_cm']:.0f}"
            )
    picture = grid(images, titles, columns=4)
    path = save_png(OUT_DIR / f"bodies_{variant}.png", picture)
    print(f"wrote {path} {picture.shape}")
    small = picture[::2, ::2]
    path = save_png(DOC_IMAGE, small)
    print(f"wrote {path} {small.shape} {path.stat().st_size / 1e3:.0f} kB")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--people", type=int, default=60, help="adults per sex from the fitting set")
    parser.add_argument("--sex", choices=("female", "male"), action="append")
    parser.add_argument("--variant", choices=sorted(VARIANTS), action="append")
    parser.add_argument("--intersections", action="store_true")
    parser.add_argument("--pictures", action="store_true")
    parser.add_argument("--pictured", action="store_true", help="intersections of the pictured bodies only")
    parser.add_argument("--report", action="store_true")
    parser.add_argument("--size", type=int, default=300)
    args = parser.parse_args(argv)
    variants = args.variant or ["girths"]
    if args.intersections:
        for v in variants:
            run_intersections(v, args.sex or ["female", "male"], args.pictured)
    elif args.pictures:
        run_pictures(variants[0], args.size)
    elif args.report:
        print(run_report(args.variant or list(VARIANTS)))
    else:
        for v in variants:
            run_fits(v, args.sex or ["female", "male"], args.people)


if __name__ == "__main__":
    main()
