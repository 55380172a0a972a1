"""Untangling operator: the paper's Table 2 on this machine, and the neural operator's error.

Run (about a minute; needs the committed ``models/untangler``)::

    python -m benchmarks.untangler [--repeats 7] [--threads 2]

Timing: median wall time of ``--repeats`` calls (after one warm-up) on 1, 5,000, 15,000 and 30,000
points of 5 layers (body + 4 garments, layered-outfit samples), for the exact operator in numpy
(PAV, its Jacobian, the min-max formula) and the neural operator in onnxruntime (values only, and
values with the in-graph Jacobian) with ``--threads`` intra-op threads. The paper's numbers (AMD Ryzen
7 2700 CPU for Buffet et al., GTX 1080 Ti GPU for theirs) are printed beside them.
Error: |O_theta - reference| in mm over the garment slots of 100,000 fresh samples (a seed used neither
in training nor in the stored evaluation) per distribution: overall, and near the surface (|f*| < 5 cm).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from service.pipeline.untangle import untangle, untangle_jacobian, untangle_minmax
from service.pipeline.untangle_onnx import ERROR_BOUND_MM, NEAR_SURFACE, NeuralUntangler
from training.untangler_data import SAMPLERS, sample_layered

SIZES = (1, 5000, 15000, 30000)
PAPER_MS = {  # Table 2, untangling operator: (Buffet et al. [8], ours)
    1: (0.04, 0.24),
    5000: (81.6, 0.68),
    15000: (238.5, 1.74),
    30000: (508.0, 3.35),
}
ERROR_SEED = 2_000_000


def median_ms(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def error_rows(neural: NeuralUntangler, n: int = 100_000) -> list[tuple[str, float, float, float]]:
    """(distribution, mean mm, near-surface mean mm, near-surface p99 mm) per sampler."""
    rows = []
    for k, sampler in enumerate(SAMPLERS):
        f, h = sampler(np.random.default_rng((ERROR_SEED, k)), n)
        h[:, 0] = -1.0
        err = 1e3 * np.abs(neural(f, h, jacobian=False).f - untangle(f, h, delta=neural.delta))[:, 1:]
        near = err[np.abs(f[:, 1:]) < NEAR_SURFACE]
        name = sampler.__name__.removeprefix("sample_")
        rows.append((name, float(err.mean()), float(near.mean()), float(np.percentile(near, 99))))
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--threads", type=int, default=2, help="onnxruntime intra-op threads")
    args = parser.parse_args(argv)
    neural = NeuralUntangler(threads=args.threads)
    f_all, h_all = sample_layered(np.random.default_rng(0), max(SIZES))
    h_all[:, 0] = -1.0

    print(
        f"## Untangling operator, 5 layers, ms (median of {args.repeats}; onnxruntime {args.threads} threads)"
    )
    print(
        "| points | paper: Buffet et al. | paper: ours (GPU) | reference PAV | reference PAV + Jacobian "
        "| reference min-max | neural | neural + Jacobian |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n in SIZES:
        f, h = f_all[:n], h_all[:n]
        times = [
            median_ms(lambda f=f, h=h: untangle(f, h), args.repeats),
            median_ms(lambda f=f, h=h: (untangle(f, h), untangle_jacobian(f, h)), args.repeats),
            median_ms(lambda f=f, h=h: untangle_minmax(f, h), args.repeats),
            median_ms(lambda f=f, h=h: neural(f, h, jacobian=False), args.repeats),
            median_ms(lambda f=f, h=h: neural(f, h), args.repeats),
        ]
        paper = PAPER_MS[n]
        print(f"| {n} | {paper[0]:.2f} | {paper[1]:.2f} | " + " | ".join(f"{t:.2f}" for t in times) + " |")

    print(f"\n## Neural operator error vs the reference, mm (target: near-surface mean <= {ERROR_BOUND_MM})")
    near = f"near surface (abs f* < {NEAR_SURFACE * 100:.0f} cm)"
    print(f"| distribution | mean | {near} mean | {near} p99 |")
    print("|---|---:|---:|---:|")
    for name, mean, near, p99 in error_rows(neural):
        print(f"| {name} | {mean:.3f} | {near:.3f} | {p99:.3f} |")


if __name__ == "__main__":
    main()
