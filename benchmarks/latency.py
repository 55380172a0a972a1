"""Pipeline latency, one request at a time, cold (every body shape new), as the service runs it.

Run (a few minutes)::

    python -m benchmarks.latency [--bodies 8] [--threads 2] [--compare REF]

For body + 1, 2, 3 and 4 garments (tops stacked, a bottom under them), ``--bodies`` random shapes
from the garments' box each, asked as a shop asks (gender, height and weight; the body built as the
service builds it, its time in "body"): p50 / p95 of the total and the p50 of every stage
(``report["seconds"]``;
no quality measures, as the service calls it; the garments' fits run side by side, so "fit" is their
wall time and fields / untangle / optimise are summed over the garments), then the throughput of two
requests at a time (two threads sharing the models, as ``ULNEF_WORKERS=2``), then the field evaluation
at 30,000 points (values only, and with x-gradients). No cache: every shape is new.

``--compare REF`` (a git ref) measures this tree against REF in the same minutes, request by request
alternating between two worker processes (``benchmarks/latency_worker.py``, one importing each tree's
``service`` and models; REF checked out with ``git worktree`` under ``build/compare/``): this machine's
speed drifts by a third between runs, so only ratios measured side by side mean much.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.untangler import median_ms
from training.drape.dataset import sample_betas

OUTFITS = (
    ("tshirt",),
    ("tshirt", "jacket"),
    ("pants", "tshirt", "jacket"),
    ("tank_top", "tshirt", "long_sleeve", "jacket"),
)
SEED = 21  # shapes used by no training and no other benchmark
STAGES = ("body", "explicit", "fit", "fields", "untangle", "optimise", "world", "repair")
REPO = Path(__file__).resolve().parents[1]
WORKER = Path(__file__).with_name("latency_worker.py")


def _label(ids) -> str:
    return f"body + {' + '.join(ids)}"


def _row(ids, reports) -> str:
    total = np.array([r["total"] for r in reports]) * 1e3
    stages = [np.median([r.get(s, 0.0) for r in reports]) * 1e3 for s in STAGES]
    return (f"| {_label(ids)} | {np.median(total):.0f} | {np.percentile(total, 95):.0f} | "
            + " | ".join(f"{v:.0f}" for v in stages) + " |")  # fmt: skip


def _header(title: str) -> None:
    print(title)
    print(f"| outfit | p50 | p95 | {' | '.join(STAGES)} |")
    print("|---|---:|---:|" + "---:|" * len(STAGES))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--bodies", type=int, default=8)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--compare", metavar="REF", help="a git ref to measure against, side by side")
    args = parser.parse_args(argv)
    betas = sample_betas(args.bodies, SEED)
    bodies = human_units(betas)
    if args.compare:
        compare(args.compare, bodies, args.threads)
        return
    from benchmarks.latency_worker import outfit_seconds
    from service.pipeline.outfit import OutfitModels, make_outfit

    models = OutfitModels.load(threads=args.threads)
    models.warm()  # what the service makes at start (service.pipeline.tryon.ModelEngine.load)
    # Warm-up, as --compare's workers: sessions, caches, allocator, and a shopper's body built and measured
    # (the body table, the measuring thread, the compiled sections: ~0.45 s the first time).
    outfit_seconds(models, ["shorts"], [0.5, 170.0, 70.0])
    _header(f"## Latency, one request at a time, {args.bodies} new body shapes per outfit (ms)")
    for k, ids in enumerate(OUTFITS):
        reports = [outfit_seconds(models, list(ids), new_body(b, k)) for b in bodies]
        print(_row(ids, reports))
    ids = OUTFITS[1]
    one = np.median([make_outfit(models, list(ids), b, measure=False).report["seconds"]["total"]
                     for b in betas])  # fmt: skip
    t0 = time.perf_counter()
    with ThreadPoolExecutor(2) as pool:
        list(pool.map(lambda b: make_outfit(models, list(ids), b, measure=False), [*betas, *betas]))
    rate = 2 * len(betas) / (time.perf_counter() - t0)
    print(f"\nthroughput, {_label(ids)}, two requests at a time: {rate:.2f} outfits/s "
          f"(one at a time: {1 / one:.2f} outfits/s)")  # fmt: skip
    rng = np.random.default_rng(0)
    x = models.explicit["tshirt"].canonical(betas[0])
    points = x[rng.integers(0, len(x), 30_000)] + rng.normal(scale=0.01, size=(30_000, 3))
    values = median_ms(lambda: models.fields("tshirt", points, betas[0]), 7)
    grads = median_ms(lambda: models.fields("tshirt", points, betas[0], True), 7)
    print(f"\nfield at 30,000 points: values {values:.1f} ms, values with x-gradients {grads:.1f} ms")


class _Worker:
    """A ``latency_worker.py`` process importing the ``service`` of the tree at ``root``."""

    def __init__(self, root: Path, threads: int):
        env = dict(os.environ, PYTHONPATH=str(root))
        self.proc = subprocess.Popen([sys.executable, str(WORKER), str(threads)], cwd=root, env=env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)  # fmt: skip
        assert json.loads(self.proc.stdout.readline())["ready"]

    def __call__(self, ids, body) -> dict:
        self.proc.stdin.write(json.dumps({"garments": list(ids), "body": list(map(float, body))}) + "\n")
        self.proc.stdin.flush()
        return json.loads(self.proc.stdout.readline())

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait()


def _worktree(ref: str) -> tuple[Path, str]:
    sha = subprocess.run(["git", "rev-parse", "--short", ref], cwd=REPO, capture_output=True, text=True,
                         check=True).stdout.strip()  # fmt: skip
    path = REPO / "build" / "compare" / sha
    if not path.exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(path), sha], cwd=REPO, check=True,
                       capture_output=True)  # fmt: skip
    return path, sha


def human_units(betas: np.ndarray) -> list[list[float]]:
    """(gender, height_cm, weight_kg) of the box bodies of ``betas (B, 3)``: what a request sends."""
    from service.pipeline.body import BodyModel, measurements_from_shape

    model = BodyModel.load()
    return [[float(b[0]), *measurements_from_shape(model, b)] for b in betas]


def new_body(body: list[float], row: int) -> list[float]:
    """``body`` 0.01 mm taller per outfit row: new to the service's body cache, the same body to a tape."""
    return [body[0], body[1] + 1e-3 * row, body[2]]


def compare(ref: str, bodies: list[list[float]], threads: int) -> None:
    """Both trees' tables and the ratio of their p50s, requests alternating between them."""
    path, sha = _worktree(ref)
    here = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True,
                          text=True).stdout.strip()  # fmt: skip
    workers = {"ref": _Worker(path, threads), "this": _Worker(REPO, threads)}
    seconds = {name: {ids: [] for ids in OUTFITS} for name in workers}
    for worker in workers.values():  # warm-up
        worker(("shorts",), [0.5, 170.0, 70.0])
    for k, ids in enumerate(OUTFITS):
        for i, body in enumerate(bodies):
            order = ("ref", "this") if i % 2 == 0 else ("this", "ref")
            for name in order:
                seconds[name][ids].append(workers[name](ids, new_body(body, k)))
    for worker in workers.values():
        worker.close()
    for name, title in (("ref", f"{ref} ({sha})"), ("this", f"this tree (HEAD {here} + changes)")):
        _header(f"## {title}: one request at a time, {len(bodies)} new body shapes per outfit (ms)")
        for ids in OUTFITS:
            print(_row(ids, seconds[name][ids]))
        print()
    print("## Ratio of p50 totals, measured alternately")
    print("| outfit | ref p50 | this p50 | this / ref |")
    print("|---|---:|---:|---:|")
    for ids in OUTFITS:
        a, b = (np.median([r["total"] for r in seconds[n][ids]]) * 1e3 for n in ("ref", "this"))
        print(f"| {_label(ids)} | {a:.0f} | {b:.0f} | {b / a:.2f} |")


if __name__ == "__main__":
    main()
