"""python -m training.drape [--train N] [--test N] [--workers W] [--out DIR] [--source population|box]:
build the drape dataset.

``--clear`` only moves the vertices of drapes already on disk out of the body (``clear_of_body``, which
new drapes get as they are made)."""

import argparse
import json
from pathlib import Path

from training.drape.dataset import DEFAULT_DIR, DatasetConfig, build_dataset, clear_dataset

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--train", type=int, default=DatasetConfig.n_train)
parser.add_argument("--test", type=int, default=DatasetConfig.n_test)
parser.add_argument("--workers", type=int, default=2)
parser.add_argument("--garments", default="", help="comma-separated ids (default: all)")
parser.add_argument("--out", type=Path, default=DEFAULT_DIR)
parser.add_argument("--source", choices=("population", "box"), default=DatasetConfig.source,
                    help="real adults (default) or the (gender, height, weight) box")
parser.add_argument("--no-corners", action="store_true", help="box: Sobol shapes only, no box corners")
parser.add_argument("--clear", action="store_true", help="only clear existing drapes of the body")
args = parser.parse_args()
if args.clear:
    print(f"moved {clear_dataset(args.out)} vertices out of the body")
    raise SystemExit(0)
garments = tuple(g for g in args.garments.split(",") if g)
config = DatasetConfig(
    args.train, args.test, garments=garments, corners=not args.no_corners, source=args.source
)
record = build_dataset(args.out, config, args.workers)
print(json.dumps(record))
