"""The slowest outfits the layering rule accepts, on the bodies at the population's edges: the bound on
a request's time (issue 55: every accepted outfit within 10 s on 2 cores).

Run (a few minutes; on a quiet machine, the times are the point)::

    python -m benchmarks.worst_case

``STACKS`` are the slowest stacks measured (``benchmarks.orders --stacks``: worn against the grain, let
down and made again); ``BODIES`` the population's corners (NHANES held-out adults nearest to them, as
``benchmarks.population`` picks tails). Each outfit is made as the service makes it
(``ModelEngine.make``, the body built first, as a new shopper's), once; the table gives its seconds,
squeeze-and-repair passes, attempts and whether it came out clean.
"""

from __future__ import annotations

import argparse
import time

from service.pipeline.tryon import ModelEngine, OutfitSpec
from service.process.paths import models_dir

STACKS = (
    ("pants", "jacket", "tshirt", "long_sleeve"),
    ("tank_top", "jacket", "tshirt", "long_sleeve"),
    ("shorts", "jacket", "long_sleeve", "tshirt"),
    ("tank_top", "tshirt", "long_sleeve", "jacket"),
)
# (label, gender, height cm, weight kg): short and light, tall, heavy (BMI ~60), of both sexes.
BODIES = (
    ("woman 146 cm 42 kg", 1.0, 146.0, 42.0),
    ("woman 180 cm 60 kg", 1.0, 180.0, 60.0),
    ("woman 160 cm 154 kg", 1.0, 160.0, 154.0),
    ("man 150 cm 45 kg", 0.0, 150.0, 45.0),
    ("man 196 cm 90 kg", 0.0, 196.0, 90.0),
    ("man 180 cm 190 kg", 0.0, 180.0, 190.0),
)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stacks", type=int, default=len(STACKS), help="the first N stacks")
    args = parser.parse_args(argv)
    engine = ModelEngine.load(models_dir(), threads=2)
    print("## The slowest accepted stacks at the population's edges (one request each, s)")
    print("| stack | body | s | passes | attempts | clean |")
    print("|---|---|---:|---:|---:|---|")
    worst = 0.0
    for ids in STACKS[: args.stacks]:
        if engine.models.refusals(list(ids)):
            print(f"| {' < '.join(ids)} | (refused) | - | - | - | - |")
            continue
        for label, gender, height, weight in BODIES:
            spec = OutfitSpec(ids, gender, height, weight)
            start = time.perf_counter()
            report = engine.make(spec).report
            seconds = time.perf_counter() - start
            worst = max(worst, seconds)
            print(f"| {' < '.join(ids)} | {label} | {seconds:.1f} | {report.get('passes', '-')} | "
                  f"{report['attempts']} | {report.get('collision_free')} |", flush=True)  # fmt: skip
    print(f"\nslowest: {worst:.1f} s")


if __name__ == "__main__":
    main()
