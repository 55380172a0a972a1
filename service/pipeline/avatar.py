"""The avatar a shop drapes its own garments on: the mean body in its rest A-pose, with its UVs and
the measurements a pattern maker asks for.

Files are Y up and face +Z (glTF's frame; Blender, CLO3D and Marvelous Designer import OBJ and glTF
that way): Anny's (x, y, z) becomes (x, z, -y), a rotation (``service.pipeline.gltf.ANNY_TO_GLTF``).
glTF is in metres by definition; OBJ carries no unit, so it is written in the unit asked for.
Girths are tape measures: the convex hull of the body's cross-section at the height where the
girth is taken (largest at the chest and the hips, smallest at the waist), arms and hands left out.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.spatial import ConvexHull

from service.pipeline.appearance import DisplayMesh
from service.pipeline.body import DEFAULT_BETA, BodyModel, measurements_from_shape
from service.pipeline.gltf import ANNY_TO_GLTF

Units = Literal["m", "cm", "mm"]
SCALE: dict[str, float] = {"m": 1.0, "cm": 100.0, "mm": 1000.0}
SKIN = (0.87, 0.72, 0.62, 1.0)
ARM_REGIONS = ("upperarm_l", "upperarm_r", "lowerarm_l", "lowerarm_r", "hand_l", "hand_r")
# Where each girth is searched (between these bones' heights) and whether it is the largest or the
# smallest cross-section there.
GIRTHS: dict[str, tuple[str, str, Literal["max", "min"]]] = {
    "chest": ("spine02", "upperarm01.L", "max"),
    "waist": ("spine04", "spine01", "min"),
    "hip": ("upperleg02.L", "spine04", "max"),
}
STEP = 0.005  # m between the heights tried


@dataclass(frozen=True)
class Avatar:
    """vertices (V, 3) m in Anny's frame, faces (F, 3), display (UVs), the shape code beta (3,), and
    measurements in metres and kilograms: height, weight_kg, girths {chest, waist, hip} and the
    heights above the floor they were taken at."""

    vertices: np.ndarray
    faces: np.ndarray
    display: DisplayMesh | None
    beta: np.ndarray
    height: float
    weight_kg: float
    girths: dict[str, float]
    girth_heights: dict[str, float]


def cross_section(vertices: np.ndarray, faces: np.ndarray, z: float) -> np.ndarray:
    """(N, 2) x, y where the edges of ``faces (F, 3)`` cross the plane at height ``z``."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    za, zb = vertices[edges[:, 0], 2], vertices[edges[:, 1], 2]
    crossing = (za - z) * (zb - z) < 0
    a, b = vertices[edges[crossing, 0]], vertices[edges[crossing, 1]]
    t = (z - a[:, 2]) / (b[:, 2] - a[:, 2])
    return (a + t[:, None] * (b - a))[:, :2]


def tape_girth(vertices: np.ndarray, faces: np.ndarray, z: float) -> float:
    """Length (m) of a tape around the cross-section at ``z``: its convex hull's perimeter."""
    points = cross_section(vertices, faces, z)
    if len(points) < 3:
        return 0.0
    return float(ConvexHull(points).area)  # in 2-D, "area" is the perimeter


def measure_girths(body: BodyModel, vertices: np.ndarray) -> tuple[dict[str, float], dict[str, float]]:
    """(girths, heights above the floor) in m of the body ``vertices (V, 3)``, arms left out."""
    arms = np.isin(body.regions, [body.region_names.index(r) for r in ARM_REGIONS])
    faces = body.faces[~arms[body.faces].any(1)]
    bones = dict(zip(body.bone_names, body.bone_heads[:, 2], strict=True))
    floor = float(vertices[:, 2].min())
    girths, heights = {}, {}
    for name, (low, high, pick) in GIRTHS.items():
        zs = np.arange(bones[low], bones[high], STEP)
        values = np.array([tape_girth(vertices, faces, z) for z in zs])
        k = int(values.argmax() if pick == "max" else values.argmin())
        girths[name], heights[name] = float(values[k]), float(zs[k] - floor)
    return girths, heights


def mean_avatar(body: BodyModel) -> Avatar:
    """The avatar: ``body`` at its mean shape (``DEFAULT_BETA``), feet on z = 0."""
    beta = np.asarray(DEFAULT_BETA, dtype=np.float64)
    vertices = body.vertices(beta)
    height_cm, weight_kg = measurements_from_shape(body, beta)
    girths, heights = measure_girths(body, vertices)  # in the bones' frame, before the feet go to 0
    vertices = vertices - [0.0, 0.0, vertices[:, 2].min()]
    return Avatar(vertices, body.faces, body.display, beta, height_cm / 100, weight_kg, girths, heights)


def avatar_info(avatar: Avatar, units: Units, file_name: str) -> dict:
    """What ``avatar.json`` says: units, axes, the shape and its measurements in ``units``."""
    s = SCALE[units]
    gender, height_cm, weight_kg = float(avatar.beta[0]), avatar.height * 100, avatar.weight_kg
    return {
        "file": file_name,
        "units": units,
        "up_axis": "+Y",
        "forward_axis": "+Z",
        "pose": "A-pose (Anny rest pose), feet on y = 0",
        "body": {"gender": gender, "height_cm": round(height_cm, 2), "weight_kg": round(weight_kg, 2)},
        "height": round(avatar.height * s, 4),
        "weight_kg": round(weight_kg, 2),
        "girths": {k: round(v * s, 4) for k, v in avatar.girths.items()},
        "girth_heights": {k: round(v * s, 4) for k, v in avatar.girth_heights.items()},
    }


def avatar_obj(avatar: Avatar, units: Units) -> str:
    """Wavefront OBJ text: Y-up positions in ``units``, texture coordinates (origin bottom left),
    one ``f v/vt`` per triangle; vertices stay welded (a UV seam only splits texture coordinates)."""
    v = (avatar.vertices @ ANNY_TO_GLTF.T) * SCALE[units]
    lines = [f"# ULNeF avatar: mean body, A-pose, Y up, units {units}", "o avatar"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in v]
    faces = avatar.faces + 1
    if avatar.display is None:
        lines += [f"f {a} {b} {c}" for a, b, c in faces]
    else:
        d = avatar.display
        lines += [f"vt {u:.6f} {1.0 - w:.6f}" for u, w in d.uv]
        corners = zip(faces, d.faces + 1, strict=True)
        lines += [f"f {a}/{ta} {b}/{tb} {c}/{tc}" for (a, b, c), (ta, tb, tc) in corners]
    return "\n".join(lines) + "\n"
