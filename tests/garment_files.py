"""Garment files made the way a shop's design tool would hand them over, by a method that is not
``training/garments`` (not an offset of the body): a skirt swept as a tube of rings, each an ellipse
around the avatar's cross-section at that height plus an ease that grows from a snug waistband to a
loose hem, never narrowing going down; and a strapless dress (``dress_tube``) swept the same way from
each cross-section's support function. Their texture seam runs down the back, so the file's vertices
are split there (OBJ by its ``vt``, GLB by duplicated vertices), written in the avatar's frame (Y up,
feet on y = 0) in the unit asked for.

    python -m tests.garment_files OUT_DIR [--edge 0.012] [--units cm]
    # skirt.obj/.mtl/.png, skirt.glb, dress.obj/.mtl/.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from service.pipeline.avatar import SCALE, cross_section
from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.gltf import ANNY_TO_GLTF


def skirt_tube(body: BodyModel, edge: float = 0.012, ease: tuple[float, float] = (0.008, 0.04), length=0.45):
    """(vertices (V, 3) Anny frame, faces (F, 3), uv (V, 2) v up) of a tube from the waist down,
    ``edge`` m between neighbours, the seam column doubled at the back (angle pi)."""
    mean = body.vertices(np.asarray(DEFAULT_BETA))
    bones = dict(zip(body.bone_names, body.bone_heads, strict=True))
    top = bones["spine03"][2]
    limbs = [i for i, r in enumerate(body.region_names) if "arm" in r or "hand" in r]
    arms = np.isin(body.regions, limbs)
    faces = body.faces[~arms[body.faces].any(1)]
    zs = top - np.arange(0.0, length + 1e-9, edge)
    half = []
    for k, z in enumerate(zs):
        xy = cross_section(mean, faces, z)
        grow = ease[0] + (ease[1] - ease[0]) * k / max(len(zs) - 1, 1)
        half.append(np.abs(xy - [0.0, bones["spine03"][1]]).max(0) + grow)
    half = np.maximum.accumulate(np.array(half), axis=0)  # never narrower below
    circumference = np.pi * half.sum(1).max()  # ~ ellipse perimeter
    n = int(np.ceil(circumference / edge))
    theta = np.linspace(-np.pi, np.pi, n + 1)  # the last column repeats the first: the seam
    rings = []
    for z, (a, b) in zip(zs, half, strict=True):
        # theta 0 at the front (-y), +-pi at the back
        y = bones["spine03"][1] - b * np.cos(theta)
        rings.append(np.stack([a * np.sin(theta), y, np.full(n + 1, z)], 1))
    return _tube(rings, zs, theta, circumference)


def dress_tube(body: BodyModel, edge: float = 0.012, ease: tuple[float, float] = (0.006, 0.07),
               below_armpit: float = 0.07, below_knee: float = 0.06):  # fmt: skip
    """(vertices (V, 3) Anny frame, faces (F, 3), uv (V, 2) v up) of a strapless shift dress: a tube
    from ``below_armpit`` m under the armpits (the upper arm's second bone) to ``below_knee`` m under
    the knees, ``edge`` m between neighbours, the seam column doubled at the back (angle pi).

    Not the skirt's ellipses: each ring is the polar curve of the *support function* of the body's
    cross-section there (arms left out) about the spine, r(theta) = max over the section's points of
    their reach along theta, plus an ease growing from a snug bodice (which the drape's friction holds
    up, as a strapless dress's boning does) to a loose hem; every angle's radius never shrinks going
    down, so the dress falls straight from the bust over the waist and around both legs together."""
    mean = body.vertices(np.asarray(DEFAULT_BETA))
    bones = dict(zip(body.bone_names, body.bone_heads, strict=True))
    top = bones["upperarm02.L"][2] - below_armpit
    bottom = bones["lowerleg01.L"][2] - below_knee
    limbs = [i for i, r in enumerate(body.region_names) if "arm" in r or "hand" in r]
    arms = np.isin(body.regions, limbs)
    faces = body.faces[~arms[body.faces].any(1)]
    centre = np.array([0.0, bones["spine03"][1]])
    zs = top - np.arange(0.0, top - bottom + 1e-9, edge)
    probe = np.linspace(-np.pi, np.pi, 361)
    directions = np.stack([np.sin(probe), -np.cos(probe)], 1)  # theta 0 at the front (-y)
    reach = np.array([((cross_section(mean, faces, z) - centre) @ directions.T).max(0) for z in zs])
    reach = np.maximum.accumulate(reach, axis=0)  # (Z, 361): never narrower below
    reach += (ease[0] + (ease[1] - ease[0]) * np.linspace(0.0, 1.0, len(zs)))[:, None]
    step = np.hypot(reach, np.gradient(reach, probe, axis=1))  # |d point / d theta|
    circumference = float(np.trapezoid(step, probe, axis=1).max())
    n = int(np.ceil(circumference / edge))
    theta = np.linspace(-np.pi, np.pi, n + 1)  # the last column repeats the first: the seam
    rings = []
    for z, r in zip(zs, reach, strict=True):
        radius = np.interp(theta, probe, r)
        xy = centre + radius[:, None] * np.stack([np.sin(theta), -np.cos(theta)], 1)
        rings.append(np.concatenate([xy, np.full((n + 1, 1), z)], 1))
    return _tube(rings, zs, theta, circumference)


def _tube(rings: list[np.ndarray], zs: np.ndarray, theta: np.ndarray, circumference: float):
    """(vertices (Z * (n + 1), 3), faces, uv (V, 2)) of a tube of ``rings`` (Z of ``(n + 1, 3)``, the
    last column repeating the first: the seam) at heights ``zs (Z,)`` and angles ``theta (n + 1,)``,
    its UVs in 5 cm texture tiles."""
    n = len(theta) - 1
    vertices = np.concatenate(rings)
    idx = np.arange(len(vertices)).reshape(len(zs), n + 1)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]
    # Outward normals: going round with theta and down the rings.
    faces_out = np.concatenate([np.stack([a, d, c], -1), np.stack([a, c, b], -1)]).reshape(-1, 3)
    u = np.tile(theta / (2 * np.pi) * circumference / 0.05, len(zs))
    v = np.repeat((zs - zs[0]) / 0.05, n + 1)
    return vertices, faces_out, np.stack([u, v], 1)


def to_file_frame(vertices: np.ndarray, floor: float, units: str) -> np.ndarray:
    """Anny frame (m, Z up) -> the avatar file's frame (Y up, feet on y = 0) in ``units``."""
    return ((vertices - [0.0, 0.0, floor]) @ ANNY_TO_GLTF.T) * SCALE[units]


def stripes(size: int = 64) -> np.ndarray:
    """(size, size, 3) a tileable woven-stripe texture in [0, 1]."""
    i, j = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
    stripe = (j // 8) % 2
    return np.stack([0.2 + 0.6 * stripe, 0.3 + 0.1 * ((i // 4) % 2), 0.5 - 0.3 * stripe], -1).astype(float)


def write_obj(out: Path, name: str, vertices, faces, uv, units: str, floor: float) -> Path:
    """``name.obj`` + ``name.mtl`` + ``name.png``; positions welded at the seam, split by ``vt``."""
    from training.render import save_png

    out.mkdir(parents=True, exist_ok=True)
    save_png(out / f"{name}.png", stripes())
    (out / f"{name}.mtl").write_text(f"newmtl cloth\nKd 1.0 1.0 1.0\nmap_Kd {name}.png\n")
    # Weld the seam's positions (a design tool writes each point once) and keep both texture coordinates.
    key = np.round(vertices / 1e-7).astype(np.int64)
    _, first, weld = np.unique(key, axis=0, return_index=True, return_inverse=True)
    p = to_file_frame(vertices[first], floor, units)
    lines = [f"mtllib {name}.mtl", "o skirt"] + [f"v {x:.7f} {y:.7f} {z:.7f}" for x, y, z in p]
    lines += [f"vt {s:.6f} {t:.6f}" for s, t in uv] + ["usemtl cloth"]
    w = weld.reshape(-1)[faces] + 1
    lines += [f"f {a}/{ta} {b}/{tb} {c}/{tc}" for (a, b, c), (ta, tb, tc) in zip(w, faces + 1, strict=True)]
    path = out / f"{name}.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


def write_glb(path: Path, vertices, faces, uv, floor: float) -> Path:
    """A GLB written by trimesh's exporter (not the service's), the texture embedded."""
    import trimesh
    from PIL import Image

    image = Image.fromarray((stripes() * 255).astype(np.uint8))
    factor = [255, 240, 230, 255]
    material = trimesh.visual.material.PBRMaterial(baseColorTexture=image, baseColorFactor=factor)
    mesh = trimesh.Trimesh(to_file_frame(vertices, floor, "m"), faces, process=False,
                           visual=trimesh.visual.TextureVisuals(uv=uv, material=material))  # fmt: skip
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(mesh.export(file_type="glb"))
    return path


def main(argv=None) -> None:
    formatter = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=formatter)
    parser.add_argument("out", type=Path)
    parser.add_argument("--edge", type=float, default=0.012)
    parser.add_argument("--units", choices=tuple(SCALE), default="m")
    args = parser.parse_args(argv)
    body = BodyModel.load()
    floor = float(body.vertices(np.asarray(DEFAULT_BETA))[:, 2].min())
    v, f, uv = skirt_tube(body, args.edge)
    print(write_obj(args.out, "skirt", v, f, uv, args.units, floor))
    print(write_glb(args.out / "skirt.glb", v, f, uv, floor))
    print(f"{len(v)} file vertices, {len(f)} faces")
    v, f, uv = dress_tube(body, args.edge)
    print(write_obj(args.out, "dress", v, f, uv, args.units, floor))
    print(f"{len(v)} file vertices, {len(f)} faces")


if __name__ == "__main__":
    main()


def write_plain_obj(path: Path, vertices: np.ndarray, faces: np.ndarray, floor: float, units="m") -> Path:
    """A bare OBJ (positions and faces only) of an Anny-frame mesh, in the avatar file's frame."""
    p = to_file_frame(vertices, floor, units)
    lines = [f"v {x:.7f} {y:.7f} {z:.7f}" for x, y, z in p] + [f"f {a} {b} {c}" for a, b, c in faces + 1]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def welded(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh with vertices at one position merged (the tube's seam column closed)."""
    key = np.round(vertices / 1e-7).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return vertices[first], inverse.reshape(-1)[faces]
