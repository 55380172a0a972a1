"""python -m training.drape [--train N] [--test N] [--workers W] [--out DIR]: build the drape dataset."""

import argparse
import json
from pathlib import Path

from training.drape.dataset import DEFAULT_DIR, DatasetConfig, build_dataset

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--train", type=int, default=DatasetConfig.n_train)
parser.add_argument("--test", type=int, default=DatasetConfig.n_test)
parser.add_argument("--workers", type=int, default=2)
parser.add_argument("--garments", default="", help="comma-separated ids (default: all)")
parser.add_argument("--out", type=Path, default=DEFAULT_DIR)
args = parser.parse_args()
config = DatasetConfig(args.train, args.test, garments=tuple(g for g in args.garments.split(",") if g))
record = build_dataset(args.out, config, args.workers)
print(json.dumps(record))
