"""Where a request's time goes: compiled kernels against numpy and Python, on one thread and on two.

Run (a few minutes)::

    python -m benchmarks.breakdown [--bodies 6]

For the outfits of ``benchmarks.latency`` (every body shape new, no quality measures), the p50 of:

- "2 threads": the request as the service runs it (the latency table's p50), and without the
  world-space squeeze and repair (``make_outfit(repair=False)``: the fit and the body map only);
- "1 thread": everything on one thread (onnxruntime, the garments' fits, closest-point blocks, the
  body map's blocks), and of that one-thread time the part spent inside onnxruntime's ``run`` (field
  and untangler networks), inside scipy's KD-tree queries (nearest vertices of the closest-point
  queries and of the body map), and the rest (numpy and Python: the geometry of the squeeze, the
  repair, the body map, the L-BFGS);
- "floor": half of onnxruntime + KD-tree, what two cores would need if all the numpy and Python work
  were free and both cores were always busy. It bounds what compiled code (numba, an extension) for
  the rest could reach without doing less work.

The timers wrap ``onnxruntime.InferenceSession.run`` and the KD-tree class that ``service.geometry.closest``
builds its trees with (installed before the models load); they add ~1 us a call.
"""

from __future__ import annotations

import argparse
import time
from contextlib import contextmanager

import numpy as np
import onnxruntime as ort
from scipy.spatial import cKDTree

import service.geometry.closest
import service.pipeline.outfit
from benchmarks.latency import OUTFITS, SEED
from service.pipeline.outfit import OutfitModels, make_outfit
from training.drape.dataset import sample_betas

SPENT = {"onnxruntime": 0.0, "kdtree": 0.0}


class _TimedTree(cKDTree):
    def query(self, *args, **kwargs):
        t0 = time.perf_counter()
        try:
            return super().query(*args, **kwargs)
        finally:
            SPENT["kdtree"] += time.perf_counter() - t0


@contextmanager
def _instrumented(threads: int):
    """Timers on onnxruntime and the KD-tree; ``threads`` for the fits and closest-point blocks."""
    run = ort.InferenceSession.run

    def timed_run(self, *args, **kwargs):
        t0 = time.perf_counter()
        try:
            return run(self, *args, **kwargs)
        finally:
            SPENT["onnxruntime"] += time.perf_counter() - t0

    saved = (
        service.geometry.closest.cKDTree, service.geometry.closest.QUERY_THREADS,
        service.pipeline.outfit.FIT_THREADS,
    )  # fmt: skip
    ort.InferenceSession.run = timed_run
    service.geometry.closest.cKDTree = _TimedTree
    service.geometry.closest.QUERY_THREADS = service.pipeline.outfit.FIT_THREADS = threads
    try:
        yield
    finally:
        ort.InferenceSession.run = run
        (
            service.geometry.closest.cKDTree, service.geometry.closest.QUERY_THREADS,
            service.pipeline.outfit.FIT_THREADS,
        ) = saved  # fmt: skip


def measure(models: OutfitModels, ids: list[str], betas: np.ndarray, repair: bool = True) -> dict[str, float]:
    """p50 (ms) over ``betas`` of the total and of the time inside onnxruntime and the KD-tree."""
    rows = []
    for beta in betas:
        for key in SPENT:
            SPENT[key] = 0.0
        t0 = time.perf_counter()
        make_outfit(models, ids, beta, measure=False, repair=repair)
        rows.append((time.perf_counter() - t0, SPENT["onnxruntime"], SPENT["kdtree"]))
    total, onnx, kd = np.median(np.array(rows) * 1e3, axis=0)
    return {"total": total, "onnxruntime": onnx, "kdtree": kd}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--bodies", type=int, default=6)
    args = parser.parse_args(argv)
    betas = sample_betas(args.bodies, SEED)
    results = {}
    for threads in (2, 1):
        with _instrumented(threads):
            models = OutfitModels.load(threads=threads)
            make_outfit(models, ["shorts"], betas[0], measure=False)  # warm-up
            results[threads] = {ids: measure(models, list(ids), betas) for ids in OUTFITS}
            if threads == 2:
                results["no repair"] = {ids: measure(models, list(ids), betas, False) for ids in OUTFITS}
    print(f"## Time per request, p50 over {args.bodies} new body shapes (ms)")
    columns = ("2 threads", "2 threads, no repair", "1 thread", "in onnxruntime", "in KD-tree")
    columns += ("numpy + Python", "floor on 2 cores")
    print(f"| outfit | {' | '.join(columns)} |")
    print("|---|" + "---:|" * len(columns))
    for ids in OUTFITS:
        two, bare, one = results[2][ids], results["no repair"][ids], results[1][ids]
        rest = one["total"] - one["onnxruntime"] - one["kdtree"]
        floor = (one["onnxruntime"] + one["kdtree"]) / 2
        print(
            f"| body + {' + '.join(ids)} | {two['total']:.0f} | {bare['total']:.0f} | {one['total']:.0f} | "
            f"{one['onnxruntime']:.0f} | {one['kdtree']:.0f} | {rest:.0f} | {floor:.0f} |"
        )


if __name__ == "__main__":
    main()
