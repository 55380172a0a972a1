"""Where a request's time goes: compiled kernels against numpy and Python, on one thread and on two.

Run (a few minutes)::

    python -m benchmarks.breakdown [--bodies 6]

For the outfits of ``benchmarks.latency`` (every body shape new, no quality measures), the p50 of:

- "2 threads": the request as the service runs it (the latency table's p50), and without the
  world-space squeeze and repair (``make_outfit(repair=False)``: the fit and the body map only);
- "1 thread": everything on one thread (onnxruntime, the garments' fits, closest-point blocks, the
  body map's blocks), and of that one-thread time the part spent inside onnxruntime's ``run`` (field
  and untangler networks), inside scipy's KD-tree queries (the body map's fallback and the
  near term's candidates; closest-point queries search a hierarchy of boxes, counted as numba),
  inside the numba kernels (``KERNELS``: closest-point search, the body map's neighbours and
  weights, strain energy, crossing tests), and the rest
  (numpy and Python: the glue of the squeeze, the repair, the fit, the L-BFGS);
- "floor": half of onnxruntime + KD-tree + numba, what two cores would need if all the numpy and
  Python work were free and both cores were always busy: what doing the same work faster could
  reach at best, without doing less of it.

Then, on 2 threads, how many cores the request keeps busy (process CPU time over wall time) up to the
body map and in the world-space stages (the squeeze and the repair, ``resolve``): where the
second core idles.

The timers wrap ``onnxruntime.InferenceSession.run``, the KD-tree class that ``service.geometry.closest``
builds its trees with, and each kernel where its caller looks it up (installed before the models
load); they add ~1 us a call.
"""

from __future__ import annotations

import argparse
import importlib
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

SPENT = {"onnxruntime": 0.0, "kdtree": 0.0, "numba": 0.0}
# (module, name) of each compiled kernel as its caller calls it
KERNELS = (
    ("service.geometry.bvh_kernel", "closest"),
    ("service.geometry.bvh_kernel", "corners"),
    ("service.geometry.bvh_kernel", "boxes"),
    ("service.geometry.bvh_kernel", "build"),
    ("service.geometry.near_vertices", "_select_k"),
    ("service.pipeline.canonical", "transfer_rows"),
    ("service.pipeline.strain", "_strain_kernel"),
    ("service.pipeline.strain", "_norms_kernel"),
    ("service.geometry.clear_of", "_clear_of_kernel"),
    ("service.geometry.intersections", "fill"),
    ("service.geometry.intersections", "pairs"),
    ("service.geometry.intersections", "corner_boxes"),
    ("service.geometry.sdf_grid", "_trilinear"),
    ("service.geometry.mesh", "_face_normals"),
    ("service.geometry.kept_queries", "_moved"),
)


def _timed(kernel):
    def call(*args):
        t0 = time.perf_counter()
        try:
            return kernel(*args)
        finally:
            SPENT["numba"] += time.perf_counter() - t0

    return call


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
    modules = {name: importlib.import_module(name) for name, _ in KERNELS}
    kernels = [(modules[m], k, getattr(modules[m], k)) for m, k in KERNELS]
    for module, name, kernel in kernels:
        setattr(module, name, _timed(kernel))
    service.geometry.closest.QUERY_THREADS = service.pipeline.outfit.FIT_THREADS = threads
    try:
        yield
    finally:
        ort.InferenceSession.run = run
        for module, name, kernel in kernels:
            setattr(module, name, kernel)
        (
            service.geometry.closest.cKDTree, service.geometry.closest.QUERY_THREADS,
            service.pipeline.outfit.FIT_THREADS,
        ) = saved  # fmt: skip


WORLD = {"wall": 0.0, "cpu": 0.0}  # the world-space stages (squeeze and repair) of the last request


@contextmanager
def _world_clock():
    """Wall and process CPU time of ``resolve`` (the squeeze and the repair) into ``WORLD``."""
    untangle = service.pipeline.outfit.resolve

    def timed(*args, **kwargs):
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            return untangle(*args, **kwargs)
        finally:
            WORLD["wall"] += time.perf_counter() - t0
            WORLD["cpu"] += time.process_time() - c0

    service.pipeline.outfit.resolve = timed
    try:
        yield
    finally:
        service.pipeline.outfit.resolve = untangle


def measure(models: OutfitModels, ids: list[str], betas: np.ndarray, repair: bool = True) -> dict[str, float]:
    """p50 (ms) over ``betas`` of the total and of the time inside onnxruntime and the KD-tree; and the
    cores kept busy (process CPU time over wall time, summed over the requests) before the world-space
    stages and in them."""
    rows, busy = [], np.zeros(4)  # (wall, cpu) before resolve, (wall, cpu) in it
    for beta in betas:
        SPENT.update(dict.fromkeys(SPENT, 0.0))
        WORLD.update(dict.fromkeys(WORLD, 0.0))
        t0, c0 = time.perf_counter(), time.process_time()
        with _world_clock():
            make_outfit(models, ids, beta, measure=False, repair=repair)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        busy += (wall - WORLD["wall"], cpu - WORLD["cpu"], WORLD["wall"], WORLD["cpu"])
        rows.append((wall, SPENT["onnxruntime"], SPENT["kdtree"], SPENT["numba"]))
    total, onnx, kd, jit = np.median(np.array(rows) * 1e3, axis=0)
    cores = (busy[1] / busy[0], busy[3] / busy[2] if busy[2] else float("nan"))
    return {"total": total, "onnxruntime": onnx, "kdtree": kd, "numba": jit, "cores": cores}


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
            # As benchmarks.latency warms up, so that the two tables compare: what the service makes at
            # start (without it, the requests made the layering profiles and pair gaps), then one request.
            models.warm()
            make_outfit(models, ["shorts"], betas[0], measure=False)
            results[threads] = {ids: measure(models, list(ids), betas) for ids in OUTFITS}
            if threads == 2:
                results["no repair"] = {ids: measure(models, list(ids), betas, False) for ids in OUTFITS}
    print(f"## Time per request, p50 over {args.bodies} new body shapes (ms)")
    columns = ("2 threads", "2 threads, no repair", "1 thread", "in onnxruntime", "in KD-tree", "in numba")
    columns += ("numpy + Python", "floor on 2 cores")
    print(f"| outfit | {' | '.join(columns)} |")
    print("|---|" + "---:|" * len(columns))
    for ids in OUTFITS:
        two, bare, one = results[2][ids], results["no repair"][ids], results[1][ids]
        compiled = one["onnxruntime"] + one["kdtree"] + one["numba"]
        print(
            f"| body + {' + '.join(ids)} | {two['total']:.0f} | {bare['total']:.0f} | {one['total']:.0f} | "
            f"{one['onnxruntime']:.0f} | {one['kdtree']:.0f} | {one['numba']:.0f} | "
            f"{one['total'] - compiled:.0f} | {compiled / 2:.0f} |"
        )
    print("\n## Cores kept busy on 2 threads (process CPU time / wall time, all requests)")
    print("| outfit | body to body map | squeeze + repair |")
    print("|---|---:|---:|")
    for ids in OUTFITS:
        before, world = results[2][ids]["cores"]
        print(f"| body + {' + '.join(ids)} | {before:.2f} | {world:.2f} |")


if __name__ == "__main__":
    main()
