"""Runtime body (numpy) vs Anny (torch): vertex parity, speed, calibration accuracy, ranges.

Run (~30 s once Anny's cache is built)::

    python -m benchmarks.body_parity

Parity uses the same 100 shapes as the export check (uniform over the supported parameter box,
seed 0). Calibration errors are measured on the generated mesh (``body_measurements``), not on
the fast path the solver uses.
"""

from __future__ import annotations

import time

import numpy as np

from export.body import PARITY_SAMPLES, PARITY_SEED, parity_errors_mm, sample_supported_betas
from service.pipeline.body import (
    SUPPORTED_HEIGHT_PARAM,
    SUPPORTED_WEIGHT_PARAM,
    BodyModel,
    body_measurements,
    measurements_from_shape,
    shape_from_measurements,
    supported_height_range_cm,
    supported_weight_range_kg,
)
from training.anny_body import anny_rest

GENDERS = (0.0, 0.5, 1.0)
CALIBRATION_GRID = 15  # heights x weights per gender
TIMING_REPEATS = 200


def _ms_per_call(fn, repeats: int = TIMING_REPEATS) -> float:
    fn()
    start = time.perf_counter()
    for _ in range(repeats):
        fn()
    return 1e3 * (time.perf_counter() - start) / repeats


def calibration_errors(body: BodyModel, gender: float) -> tuple[float, float, float]:
    """Max |height error| cm, max |mass error| kg and ms per request over a request grid."""
    lo, hi = supported_height_range_cm(body, gender)
    height_err = mass_err = seconds = 0.0
    n = 0
    for height_cm in np.linspace(lo, hi, CALIBRATION_GRID):
        for weight_kg in np.linspace(*supported_weight_range_kg(body, gender, height_cm), CALIBRATION_GRID):
            start = time.perf_counter()
            beta = shape_from_measurements(body, gender, height_cm, weight_kg)
            seconds += time.perf_counter() - start
            height_m, mass_kg = body_measurements(body.vertices(beta), body.faces)
            height_err = max(height_err, abs(100.0 * height_m - height_cm))
            mass_err = max(mass_err, abs(mass_kg - weight_kg))
            n += 1
    return height_err, mass_err, 1e3 * seconds / n


def main() -> None:
    start = time.perf_counter()
    body = BodyModel.load()
    load_s = time.perf_counter() - start
    betas = sample_supported_betas(PARITY_SAMPLES, PARITY_SEED)
    err = parity_errors_mm(body, betas)
    beta = betas[0]
    runtime_ms = _ms_per_call(lambda: body.vertices(beta))
    batch_ms = _ms_per_call(lambda: body.vertices_batch(betas), 10) / len(betas)
    anny_ms = _ms_per_call(lambda: anny_rest(betas), 3) / len(betas)

    print(f"## Runtime body vs anny ({body.metadata['anny_version']}, {body.n_vertices} vertices)")
    print("| metric | value |")
    print("|---|---|")
    print(f"| max vertex error, {PARITY_SAMPLES} shapes (mm) | {err.max():.2e} |")
    print(f"| mean vertex error (mm) | {err.mean():.2e} |")
    print(f"| runtime, one body (ms) | {runtime_ms:.3f} |")
    print(f"| runtime, batch of {len(betas)} (ms per body) | {batch_ms:.3f} |")
    print(f"| anny, batch of {len(betas)} (ms per body) | {anny_ms:.3f} |")
    print(f"| runtime load incl. volume tensor (s) | {load_s:.2f} |")

    print(
        f"\n## Calibration ({CALIBRATION_GRID}x{CALIBRATION_GRID} requests per gender, measured on the mesh)"
    )
    print("| gender | max abs height error (cm) | max abs mass error (kg) | ms per request |")
    print("|---|---|---|---|")
    for g in GENDERS:
        h_err, m_err, ms = calibration_errors(body, g)
        print(f"| {g:g} | {h_err:.1e} | {m_err:.1e} | {ms:.2f} |")

    print(
        f"\n## Supported range (height param {SUPPORTED_HEIGHT_PARAM}, weight param {SUPPORTED_WEIGHT_PARAM})"
    )
    print("| gender | height cm | weight kg at min height | at mid height | at max height |")
    print("|---|---|---|---|---|")
    for g in GENDERS:
        lo, hi = supported_height_range_cm(body, g)
        ranges = [supported_weight_range_kg(body, g, h) for h in (lo, (lo + hi) / 2, hi)]
        cells = " | ".join(f"{a:.1f}-{b:.1f}" for a, b in ranges)
        print(f"| {g:g} | {lo:.1f}-{hi:.1f} | {cells} |")

    print("\n## Box corners")
    print("| gender | height param | weight param | height cm | mass kg | BMI |")
    print("|---|---|---|---|---|---|")
    for g in (0.0, 1.0):
        for hp in SUPPORTED_HEIGHT_PARAM:
            for wp in SUPPORTED_WEIGHT_PARAM:
                height_cm, mass_kg = measurements_from_shape(body, np.array([g, hp, wp]))
                bmi = mass_kg / (height_cm / 100.0) ** 2
                print(f"| {g:g} | {hp:g} | {wp:g} | {height_cm:.1f} | {mass_kg:.1f} | {bmi:.1f} |")
    print(f"\ntotal {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
