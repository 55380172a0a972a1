"""Export ``models/body/mean_sdf.npz``: the mean body's signed distance on a grid
(``service.geometry.sdf_grid``).

    python -m export.body_sdf [--spacing 0.006]

Sampled from the exact closest-point query of the canonical (mean) body over its bounding box padded
by ``PAD``; a few minutes on 2 cores. The export checks the written grid against the exact distance on
points near the body and raises above ``TOLERANCE_MM``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from service.geometry.closest import signed_distance
from service.geometry.sdf_grid import SdfGrid
from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.canonical import CanonicalSpace
from service.process.paths import models_dir

PAD = 0.12  # m around the body's bounding box: the loosest garment hangs within it
CLIP = 0.1  # m
TOLERANCE_MM = 0.5  # 99th percentile of the error at garment vertices
FILE = "body/mean_sdf.npz"


def exact_sdf(space: CanonicalSpace):
    return lambda x: signed_distance(space.closest, x)


def garment_points(space: CanonicalSpace, clip: float) -> np.ndarray:
    """Where the grid is used: every catalog garment's rest vertices within ``clip / 2`` of the body."""
    from service.pipeline.catalog import load_catalog

    x = np.concatenate([g.vertices for g in load_catalog().values()])
    return x[np.abs(signed_distance(space.closest, x)[0]) < clip / 2]


def check(grid: SdfGrid, space: CanonicalSpace) -> dict[str, float]:
    """Grid error against the exact distance, mm, where garments are (hands, face and feet, which no
    garment covers, have up to ~1 cm between fingers and toes: the medial axes are finer than the grid)."""
    x = garment_points(space, grid.clip)
    sdf = exact_sdf(space)
    err = np.abs(grid(x, sdf)[0] - sdf(x)[0]) * 1e3
    return {"points": len(x), "mean": err.mean(), "p99": np.percentile(err, 99), "max": err.max()}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--spacing", type=float, default=0.006)
    args = parser.parse_args(argv)
    body = BodyModel.load(models_dir() / "body" / "anny_shape.npz")
    space = CanonicalSpace.build(body.vertices(np.asarray(DEFAULT_BETA)), body.faces)
    sdf = exact_sdf(space)
    lo, hi = space.mean_vertices.min(0) - PAD, space.mean_vertices.max(0) + PAD
    t0 = time.perf_counter()
    grid = SdfGrid.sample(sdf, lo, hi, args.spacing, CLIP)
    path = models_dir() / FILE
    grid.save(path)
    err = check(SdfGrid.load(path), space)
    print(
        f"{path}: grid {grid.values.shape} at {args.spacing * 1e3:.0f} mm, "
        f"{path.stat().st_size / 1e6:.1f} MB, {time.perf_counter() - t0:.0f} s; error on {err['points']} "
        f"garment vertices: mean {err['mean']:.3f} mm, 99% {err['p99']:.3f} mm, max {err['max']:.2f} mm"
    )
    if err["p99"] > TOLERANCE_MM:
        raise SystemExit(f"grid error {err['p99']:.2f} mm above {TOLERANCE_MM} mm: use a finer --spacing")


if __name__ == "__main__":
    main()
