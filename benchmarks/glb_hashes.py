"""The sha256 of the GLB of fixed requests: a refactor that must not change behaviour prints the same.

Run (about three minutes on 2 cores)::

    python -m benchmarks.glb_hashes [--save hashes.json] [--against hashes.json]

The requests: ``benchmarks.outfits``' outfits on its 3 held-out bodies, and the first ``--pairs`` (20)
ordered pairs of catalog garments (inner first, sorted ids) on the first of those bodies, each made as
the service makes it (neural untangler, repair, no quality measures) and written as a plain GLB with
the body. ``--against`` compares with a saved run and exits 1 naming every request whose bytes differ.
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import sys
from pathlib import Path

import numpy as np

from benchmarks.outfits import BODY_SEED, OUTFITS
from service.pipeline.gltf import outfit_glb
from service.pipeline.outfit import OutfitModels, make_outfit
from service.pipeline.tryon import glb_layers
from training.drape.dataset import sample_betas


def requests(models: OutfitModels, pairs: int) -> list[tuple[tuple[str, ...], int, np.ndarray]]:
    """(garment ids inner to outer, body index, beta (3,)) of every fixed request."""
    betas = sample_betas(3, BODY_SEED)
    out = [(ids, b, beta) for ids in OUTFITS for b, beta in enumerate(betas)]
    ordered = itertools.permutations(sorted(models.catalog), 2)
    return out + [(ids, 0, betas[0]) for ids in itertools.islice(ordered, pairs)]


def glb_sha256(models: OutfitModels, ids: tuple[str, ...], beta: np.ndarray) -> str:
    """sha256 (hex) of the plain GLB, body included, of one request."""
    outfit = make_outfit(models, list(ids), beta, measure=False)
    body = (outfit.body_vertices, outfit.body_faces)
    return hashlib.sha256(outfit_glb(glb_layers(outfit.garments, models.catalog, body))).hexdigest()


def main(argv=None) -> None:
    formatter = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=formatter)
    parser.add_argument("--pairs", type=int, default=20)
    parser.add_argument("--save", type=Path)
    parser.add_argument("--against", type=Path)
    args = parser.parse_args(argv)
    models = OutfitModels.load()
    models.warm()
    hashes = {}
    print("| outfit (inner to outer) | body | GLB sha256 |")
    print("|---|---:|---|")
    for ids, b, beta in requests(models, args.pairs):
        key = f"{'<'.join(ids)} @ {b}"
        hashes[key] = glb_sha256(models, ids, beta)
        print(f"| {' < '.join(ids)} | {b} | {hashes[key][:16]} |", flush=True)
    if args.save:
        args.save.write_text(json.dumps(hashes, indent=1) + "\n")
    if args.against:
        before = json.loads(args.against.read_text())
        differ = [k for k in hashes if before.get(k) != hashes[k]]
        print(f"\n{len(hashes) - len(differ)} of {len(hashes)} GLBs byte-identical to {args.against}")
        if differ:
            print("differ: " + "; ".join(differ))
            sys.exit(1)


if __name__ == "__main__":
    main()
