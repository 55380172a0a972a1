"""Pictures of the neural fields (paper Figure 4): ``python -m training.fields.pictures``.

Writes to ``docs/images``:
- ``fields_slices.png``: per garment, a frontal slice (x-z plane through the garment's centre) of the
  learned f and h at the mean shape, with their zero contours (f = 0 black, h = 0 white dashed) and the
  ground-truth garment's cross-section (dots);
- ``fields_surfaces.png``: marching-cubes surfaces of the learned f = 0, trimmed to h < 0 (the
  garment; beyond the openings the zero set of a signed distance continues), beside the explicit mesh.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from skimage.measure import marching_cubes  # noqa: E402

from service.pipeline.body import DEFAULT_BETA  # noqa: E402
from service.pipeline.fields import FieldSet  # noqa: E402
from service.process.paths import REPO_ROOT  # noqa: E402
from training.fields.train import Surfaces  # noqa: E402
from training.pictures import GARMENT_COLORS  # noqa: E402
from training.render import PALETTE, MeshLayer, grid, render_views, save_png  # noqa: E402

BETA = np.asarray(DEFAULT_BETA)


def slice_panel(fig, axes, fields: FieldSet, surfaces: Surfaces, gid: str, resolution: int = 220) -> None:
    s = surfaces(BETA)
    lo, hi = s.vertices.min(0) - 0.08, s.vertices.max(0) + 0.08
    y0 = float(np.median(s.vertices[:, 1]))
    xs, zs = np.linspace(lo[0], hi[0], resolution), np.linspace(lo[2], hi[2], resolution)
    gx, gz = np.meshgrid(xs, zs)
    pts = np.stack([gx.ravel(), np.full(gx.size, y0), gz.ravel()], 1)
    out = fields(gid, pts, BETA)
    f, h = out.f.reshape(gx.shape), out.h.reshape(gx.shape)
    near = np.abs(s.vertices[:, 1] - y0) < 0.004
    for ax, values, name in ((axes[0], f, "f"), (axes[1], h, "h")):
        im = ax.imshow(
            np.clip(values, -0.1, 0.1), origin="lower", extent=(lo[0], hi[0], lo[2], hi[2]),
            cmap="RdBu_r", vmin=-0.1, vmax=0.1,
        )  # fmt: skip
        ax.contour(gx, gz, f, levels=[0.0], colors="black", linewidths=1.2)
        ax.contour(gx, gz, h, levels=[0.0], colors="white", linewidths=1.2, linestyles="dashed")
        ax.plot(s.vertices[near, 0], s.vertices[near, 2], ".", color="gold", markersize=1.5)
        ax.set_title(f"{gid}: learned {name} (m), y = {y0:.2f}", fontsize=9)
        ax.set_aspect("equal")
        ax.tick_params(labelsize=6)
    fig.colorbar(im, ax=axes, shrink=0.7)


def learned_surface(fields: FieldSet, surfaces: Surfaces, gid: str, step: float = 0.006):
    """Marching cubes of the learned f = 0 around the garment, keeping triangles where h < 0."""
    s = surfaces(BETA)
    lo, hi = s.vertices.min(0) - 0.03, s.vertices.max(0) + 0.03
    axes = [np.arange(a, b, step) for a, b in zip(lo, hi, strict=True)]
    grid_pts = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    f = np.concatenate([fields(gid, c, BETA).f for c in np.array_split(grid_pts, 20)])
    verts, faces, _, _ = marching_cubes(f.reshape([len(a) for a in axes]), 0.0, spacing=(step,) * 3)
    verts += lo
    centres = verts[faces].mean(1)
    keep = fields(gid, centres, BETA).h < 0
    return verts, faces[keep]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "images")
    parser.add_argument("--garments", default="")
    args = parser.parse_args(argv)
    fields = FieldSet()
    ids = [g for g in (args.garments.split(",") if args.garments else fields.fields) if g != "body"]
    fig, axes = plt.subplots(len(ids), 2, figsize=(9, 3.6 * len(ids)))
    for row, gid in zip(np.atleast_2d(axes), ids, strict=True):
        slice_panel(fig, row, fields, Surfaces(gid), gid)
    args.out.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out / "fields_slices.png", dpi=90)
    images, titles = [], []
    for gid in ids:
        surfaces = Surfaces(gid)
        verts, faces = learned_surface(fields, surfaces, gid)
        s = surfaces(BETA)
        color = GARMENT_COLORS.get(gid, PALETTE["rose"])
        images.append(render_views([MeshLayer(verts, faces, color)], ("front", "side"), 300))
        titles.append(f"{gid}: marching cubes of learned f = 0 where h < 0")
        images.append(render_views([MeshLayer(s.vertices, s.faces, color)], ("front", "side"), 300))
        titles.append(f"{gid}: explicit model mesh (ground truth)")
    save_png(args.out / "fields_surfaces.png", grid(images, titles, columns=2))
    print(f"wrote fields_slices.png and fields_surfaces.png to {args.out}")


if __name__ == "__main__":
    main()
