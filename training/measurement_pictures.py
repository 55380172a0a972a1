"""Where the tape goes: ``python -m training.measurement_pictures``.

Writes ``docs/images/measurements.png``: front and side views of light and heavy male and female
bodies (``shape_from_measurements``) with the four tapes of ``service.pipeline.measurements``
drawn as thin tubes along their hulls (chest or bust, natural waist, NHANES's iliac waist, hip) and
the girths in the titles.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from service.pipeline.body import BodyModel, shape_from_measurements
from service.pipeline.measurements import TAPES, BodyMeasurements, landmarks, measure
from service.process.paths import REPO_ROOT
from training.render import PALETTE, MeshLayer, grid, render_views, save_png, text_strip

# (label, gender, height cm, weight kg)
BODIES = (
    ("man", 0.0, 178.0, 62.0),
    ("man", 0.0, 178.0, 100.0),
    ("woman", 1.0, 165.0, 52.0),
    ("woman", 1.0, 165.0, 75.0),
)
TAPE_COLORS = {"chest": "brick", "waist": "teal", "waist_iliac": "mustard", "hip": "plum"}
TAPE_LABELS = {"chest": "chest/bust", "waist": "natural waist", "waist_iliac": "iliac waist", "hip": "hip"}
TUBE_RADIUS_M = 0.008
TUBE_SIDES = 8


def tube(
    loop: np.ndarray, radius: float = TUBE_RADIUS_M, sides: int = TUBE_SIDES
) -> tuple[np.ndarray, np.ndarray]:
    """A closed tube mesh (vertices (K * sides, 3), faces (2 K sides, 3)) of ``radius`` around the
    horizontal closed polyline ``loop (K, 3)``, K >= 2."""
    loop = np.asarray(loop, dtype=np.float64)
    tangent = np.roll(loop, -1, axis=0) - np.roll(loop, 1, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    up = np.array([0.0, 0.0, 1.0])
    side = np.cross(tangent, up)
    side /= np.maximum(np.linalg.norm(side, axis=1, keepdims=True), 1e-12)
    angle = 2 * np.pi * np.arange(sides) / sides
    ring = np.cos(angle)[None, :, None] * side[:, None] + np.sin(angle)[None, :, None] * up
    vertices = (loop[:, None] + radius * ring).reshape(-1, 3)
    k = np.arange(len(loop))[:, None]
    s = np.arange(sides)[None, :]
    a = k * sides + s
    b = ((k + 1) % len(loop)) * sides + s
    c = ((k + 1) % len(loop)) * sides + (s + 1) % sides
    d = k * sides + (s + 1) % sides
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return vertices, faces


def layers_of(vertices: np.ndarray, faces: np.ndarray, m: BodyMeasurements) -> list[MeshLayer]:
    out = [MeshLayer(vertices, faces, PALETTE["skin"])]
    for name in TAPES:
        out.append(MeshLayer(*tube(m.tapes[name]), PALETTE[TAPE_COLORS[name]], name))
    return out


def title_of(label: str, m: BodyMeasurements) -> str:
    return (
        f"{label} {m.height_cm:.0f} cm {m.weight_kg:.0f} kg: chest {m.chest_cm:.1f}, waist {m.waist_cm:.1f}, "
        f"iliac waist {m.waist_iliac_cm:.1f}, hip {m.hip_cm:.1f} cm"
    )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "images")
    parser.add_argument("--size", type=int, default=440)
    args = parser.parse_args(argv)
    body = BodyModel.load()
    marks = landmarks(body)
    images, titles = [], []
    for label, gender, height_cm, weight_kg in BODIES:
        v = body.vertices(shape_from_measurements(body, gender, height_cm, weight_kg))
        m = measure(v, body.faces, marks)
        images.append(render_views(layers_of(v, body.faces, m), ("front", "side"), args.size))
        titles.append(title_of(label, m))
        print(titles[-1])
    picture = grid(images, titles, columns=2)
    legend = ", ".join(f"{TAPE_LABELS[name]}: {TAPE_COLORS[name]}" for name in TAPES)
    picture = np.concatenate(
        [text_strip(f"tapes (convex hulls of the torso's sections): {legend}", picture.shape[1]), picture]
    )
    path = save_png(args.out / "measurements.png", picture)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
