"""Export the runtime body model ``models/body/anny_shape.npz`` from Anny (offline, torch).

Refresh the file (about 10 s once Anny's cache is built; the first build takes ~60 s)::

    python -m export.body

With gender, height and weight the only free phenotypes, Anny's rest vertices are exactly
multilinear in the hat interpolation coefficients of those three phenotypes over their anchors
(see ``service.pipeline.body``), so the runtime only needs the 2 x 2 x 3 "corner" bodies at the anchors.
They are stored as float32 (rounding error < 1e-4 mm). The export is a contract plus a check: it
reloads the written file through ``service.pipeline.body.BodyModel`` and raises unless it reproduces Anny
within ``PARITY_TOLERANCE_MM`` on random shapes from the supported range.

npz contents:
    corner_vertices (2, 2, 3, V, 3) float32  rest vertices at (gender, height, weight) anchors
    anchors_gender (2,), anchors_height (2,), anchors_weight (3,) float64
    faces (F, 3) int32                       watertight, outward oriented
    uv (T, 2) float32, face_uv (F, 3) int32   Anny's texture coordinates (origin bottom left), per corner
    regions (V,) uint8, region_names (R,) str  coarse body part of each vertex
    bone_names (J,) str, bone_heads (J, 3) float64  joint positions at DEFAULT_BETA
    local_names (L,) str, local_deltas (L, 2, V, 3) float32  each local change's displacement at +1
                                             and at -1 (its "-incr" and "-decr" targets)
    beta_labels (3,) str, fixed_phenotype_names (P,) str, fixed_phenotype_values (P,) float64,
    topology, anny_version: str scalars
"""

from __future__ import annotations

import argparse
import importlib.metadata
import re
from pathlib import Path

import numpy as np

from service.pipeline.body import (
    DEFAULT_BETA,
    SHAPE_BOUNDS,
    SUPPORTED_HEIGHT_PARAM,
    SUPPORTED_WEIGHT_PARAM,
    BodyModel,
)
from service.process.paths import models_dir
from training.anny_body import (
    BETA_LABELS,
    FIXED_PHENOTYPES,
    LOCAL_CHANGES,
    TOPOLOGY,
    anny_faces,
    anny_rest,
    anny_rest_extended,
    bone_labels,
    dominant_bone,
    load_anny,
)

PARITY_TOLERANCE_MM = 0.1
PARITY_SAMPLES = 100
PARITY_SEED = 0

REGION_NAMES = (
    "head",
    "torso",
    "upperarm_l",
    "upperarm_r",
    "lowerarm_l",
    "lowerarm_r",
    "hand_l",
    "hand_r",
    "upperleg_l",
    "upperleg_r",
    "lowerleg_l",
    "lowerleg_r",
    "foot_l",
    "foot_r",
)
# Bone-name patterns (Anny/MakeHuman rig, ".L" is the body's left, +X) -> region; first match wins.
# Sided regions get the suffix of the bone.
_BONE_REGION_RULES = (
    (r"^(neck\d*|head|eye|jaw|tongue|special|oris|levator|temporalis|orbicularis)", "head"),
    (r"^(root|pelvis|spine|clavicle|shoulder|breast)", "torso"),
    (r"^upperarm", "upperarm"),
    (r"^lowerarm", "lowerarm"),
    (r"^(wrist|finger|metacarpal)", "hand"),
    (r"^upperleg", "upperleg"),
    (r"^lowerleg", "lowerleg"),
    (r"^(foot|toe)", "foot"),
)


def bone_region(bone: str) -> str:
    """Coarse region name of an Anny bone, e.g. ``"finger2-1.L" -> "hand_l"``."""
    for pattern, region in _BONE_REGION_RULES:
        if re.match(pattern, bone):
            if region in ("head", "torso"):
                return region
            side = {"L": "_l", "R": "_r"}.get(bone.rsplit(".", 1)[-1]) if "." in bone else None
            if side is None:
                raise ValueError(f"bone {bone!r} maps to sided region {region!r} but has no .L/.R suffix")
            return region + side
    raise ValueError(f"bone {bone!r} matches no body region rule")


def region_labels(dominant: np.ndarray, bones: list[str]) -> np.ndarray:
    """Region index ``(V,) uint8`` into ``REGION_NAMES`` from each vertex's dominant bone ``(V,) int``."""
    bone_to_region = np.array([REGION_NAMES.index(bone_region(b)) for b in bones], dtype=np.uint8)
    return bone_to_region[dominant]


def build_arrays() -> dict[str, np.ndarray]:
    """All arrays of the npz, straight from Anny."""
    model = load_anny()
    anchors = [model.anchors[label].detach().double().numpy() for label in BETA_LABELS]
    grid = np.stack(np.meshgrid(*anchors, indexing="ij"), axis=-1)  # (2, 2, 3, 3)
    corners = anny_rest(grid.reshape(-1, 3)).vertices  # (12, V, 3) float64
    corners = corners.reshape(*grid.shape[:3], *corners.shape[1:])

    # Local changes add a fixed displacement, the same at every phenotype, linear on each side of 0
    # (checked by ``parity_errors_mm`` on extended shapes).
    n_local = len(LOCAL_CHANGES)
    base = anny_rest_extended(np.array([DEFAULT_BETA]), np.zeros((1, n_local)))[0]
    unit = np.concatenate([np.eye(n_local), -np.eye(n_local)])
    deltas = anny_rest_extended(np.repeat([DEFAULT_BETA], 2 * n_local, axis=0), unit) - base
    deltas = deltas.reshape(2, n_local, *base.shape).transpose(1, 0, 2, 3)

    bones = bone_labels()
    mean = anny_rest(np.array([DEFAULT_BETA]))
    names, values = zip(*FIXED_PHENOTYPES.items(), strict=True)
    return {
        "corner_vertices": corners.astype(np.float32),
        "anchors_gender": anchors[0],
        "anchors_height": anchors[1],
        "anchors_weight": anchors[2],
        "faces": anny_faces().astype(np.int32),
        # Anny's texture coordinates (OBJ convention: origin bottom left) and, per face corner, which.
        "uv": model.texture_coordinates.detach().numpy().astype(np.float32),
        "face_uv": model.face_texture_coordinate_indices.detach().numpy().astype(np.int32),
        "regions": region_labels(dominant_bone(), bones),
        "region_names": np.array(REGION_NAMES),
        "bone_names": np.array(bones),
        "bone_heads": mean.bone_heads[0],
        "beta_labels": np.array(BETA_LABELS),
        "local_names": np.array(list(LOCAL_CHANGES)),
        "local_deltas": deltas.astype(np.float32),
        "fixed_phenotype_names": np.array(names),
        "fixed_phenotype_values": np.array(values, dtype=np.float64),
        "topology": np.array(TOPOLOGY),
        "anny_version": np.array(importlib.metadata.version("anny")),
    }


def sample_supported_betas(n: int, seed: int) -> np.ndarray:
    """Betas ``(n, 3)`` uniform over gender [0, 1] x the supported height/weight parameter box."""
    rng = np.random.default_rng(seed)
    lo = np.array([0.0, SUPPORTED_HEIGHT_PARAM[0], SUPPORTED_WEIGHT_PARAM[0]])
    hi = np.array([1.0, SUPPORTED_HEIGHT_PARAM[1], SUPPORTED_WEIGHT_PARAM[1]])
    return lo + (hi - lo) * rng.uniform(size=(n, 3))


def parity_errors_mm(body: BodyModel, betas: np.ndarray) -> np.ndarray:
    """Per-vertex distance ``(B, V)`` in mm between the runtime body and Anny for betas ``(B, 3)``."""
    return 1e3 * np.linalg.norm(body.vertices_batch(betas) - anny_rest(betas).vertices, axis=-1)


def sample_extended_shapes(n: int, seed: int) -> np.ndarray:
    """Shapes ``(n, 3 + L)`` uniform over ``SHAPE_BOUNDS`` (extrapolated phenotypes, local changes)."""
    lo, hi = np.array(SHAPE_BOUNDS, dtype=np.float64).T
    return lo + (hi - lo) * np.random.default_rng(seed).uniform(size=(n, len(lo)))


def extended_parity_errors_mm(body: BodyModel, shapes: np.ndarray) -> np.ndarray:
    """Per-vertex distance ``(B, V)`` in mm between the runtime body and the extended Anny."""
    anny = anny_rest_extended(shapes[:, :3], shapes[:, 3:])
    return 1e3 * np.linalg.norm(body.shape_vertices_batch(shapes) - anny, axis=-1)


def export(path: Path) -> BodyModel:
    """Write the npz to ``path``, reload it with the runtime and check parity against Anny."""
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **build_arrays())
    body = BodyModel.load(path)
    err = np.concatenate(
        [
            parity_errors_mm(body, sample_supported_betas(PARITY_SAMPLES, PARITY_SEED)).ravel(),
            extended_parity_errors_mm(body, sample_extended_shapes(PARITY_SAMPLES, PARITY_SEED)).ravel(),
        ]
    )
    if err.max() >= PARITY_TOLERANCE_MM:
        raise RuntimeError(f"runtime body differs from Anny by {err.max():.4f} mm >= {PARITY_TOLERANCE_MM}")
    print(
        f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB); parity vs anny over {PARITY_SAMPLES} shapes: "
        f"max {err.max():.2e} mm, mean {err.mean():.2e} mm"
    )
    return body


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=models_dir() / "body" / "anny_shape.npz")
    export(parser.parse_args().out)


if __name__ == "__main__":
    main()
