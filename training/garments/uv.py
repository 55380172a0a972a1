"""UVs for the procedural garments: one cylinder chart per body part, seams where a tailor puts them.

Each garment face belongs to the body part nearest to it (torso, either arm, either leg, from the
mean body's region labels); each part is a cylinder around its bones (pelvis to neck, shoulder to
wrist, hip to ankle: inside the limb, so the cloth never crosses the axis). u is arc length
around the axis (angle x the chart's median radius of the garment there), v is length along it, both
in metres divided by the fabric's tile size, so a tileable texture keeps its scale on every part.
The angle is cut at the back (+Y, the body faces -Y): seams run down the back and where a sleeve or
leg meets the torso, like the seams of sewn cloth. A seam splits vertices (``DisplayMesh``); the
simulation mesh stays welded.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from service.pipeline.appearance import DisplayMesh
from service.pipeline.body import DEFAULT_BETA

# chart: (body regions, the bones its axis runs through, in order)
CHARTS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "torso": (("torso", "head"), ("spine05", "neck01")),
    "arm_l": (("upperarm_l", "lowerarm_l", "hand_l"), ("upperarm01.L", "lowerarm01.L", "wrist.L")),
    "arm_r": (("upperarm_r", "lowerarm_r", "hand_r"), ("upperarm01.R", "lowerarm01.R", "wrist.R")),
    "leg_l": (("upperleg_l", "lowerleg_l", "foot_l"), ("foot.L", "lowerleg01.L", "upperleg01.L")),
    "leg_r": (("upperleg_r", "lowerleg_r", "foot_r"), ("foot.R", "lowerleg01.R", "upperleg01.R")),
}
FORWARD = np.array([0.0, -1.0, 0.0])  # Anny's body faces -Y; the seam is opposite
NEAR_AXIS = 0.3  # a face closer to its chart's axis than this x the chart's radius takes another chart


def axis_coordinates(points: np.ndarray, polyline: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(angle (N,), length along (N,), radial distance (N,)) of ``points (N, 3)`` around the bent axis
    ``polyline (K, 3)``: each point takes its nearest segment (the end segments extended), the angle is
    measured from the front (FORWARD made normal to that segment) and lengths add up along the axis."""
    a, b = polyline[:-1], polyline[1:]
    length = np.linalg.norm(b - a, axis=1)
    axis = (b - a) / length[:, None]
    rel = points[:, None, :] - a[None]  # (N, S, 3)
    s = np.einsum("nsd,sd->ns", rel, axis)
    lo = np.where(np.arange(len(a)) == 0, -np.inf, 0.0)
    hi = np.where(np.arange(len(a)) == len(a) - 1, np.inf, length)
    clamped = np.clip(s, lo, hi)
    dist = np.linalg.norm(rel - clamped[..., None] * axis[None], axis=2)
    k = dist.argmin(1)
    rows = np.arange(len(points))
    e1 = FORWARD - (axis @ FORWARD)[:, None] * axis
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(axis, e1)
    r = rel[rows, k]
    angle = np.arctan2(np.einsum("nd,nd->n", r, e2[k]), np.einsum("nd,nd->n", r, e1[k]))
    along = np.concatenate([[0.0], np.cumsum(length)])[k] + s[rows, k]
    radial = np.linalg.norm(r - s[rows, k, None] * axis[k], axis=1)
    return angle, along, radial


def cylinder_uv(vertices: np.ndarray, faces: np.ndarray, body, tile: float) -> DisplayMesh:
    """Display mesh of a garment ``vertices (V, 3)``, ``faces (F, 3)`` on the mean shape of ``body``
    (a ``BodyModel``: its vertices, region labels and bones); ``tile`` (m) is the texture's period."""
    body_vertices = body.vertices(np.asarray(DEFAULT_BETA))
    regions, region_names, bones = body.regions, list(body.region_names), list(body.bone_names)
    region_chart = np.full(len(region_names), -1)
    coords = []  # per chart: (angle, along, radial) of every garment vertex
    for c, (parts, chain) in enumerate(CHARTS.values()):
        region_chart[[region_names.index(p) for p in parts]] = c
        coords.append(axis_coordinates(vertices, body.bone_heads[[bones.index(b) for b in chain]]))
    angle, along, radial = (np.stack([x[i] for x in coords], axis=1) for i in range(3))  # (V, C)
    vertex_chart = region_chart[regions[cKDTree(body_vertices).query(vertices)[1]]]
    radius = np.array([np.median(radial[vertex_chart == c, c]) if np.any(vertex_chart == c) else 1.0
                       for c in range(len(CHARTS))])  # fmt: skip
    # A face's chart: the one most of its corners are nearest to (the first corner's on a tie), unless
    # the face lies near that chart's axis (the crotch below the torso's): then the chart it is
    # farthest from the axis of, relative to that chart's radius.
    corners = vertex_chart[faces]
    votes = (corners[:, :, None] == corners[:, None, :]).sum(2)
    face_chart = corners[np.arange(len(faces)), votes.argmax(1)]
    clearance = radial[faces].min(1) / radius  # (F, C)
    near = clearance[np.arange(len(faces)), face_chart] < NEAR_AXIS
    face_chart[near] = clearance[near].argmax(1)
    sim = faces.reshape(-1)
    chart = np.repeat(face_chart, 3)
    theta = angle[sim, chart]
    # Corners of one face on one branch of the angle: a face across the cut gets the 2 pi shifted copy.
    branch = np.round((np.repeat(theta[0::3], 3) - theta) / (2 * np.pi)).astype(np.int64)
    key = (sim * len(CHARTS) + chart) * 3 + (branch + 1)
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    u = (theta + 2 * np.pi * branch) * radius[chart]
    v = -along[sim, chart]  # glTF's v runs down the image: the texture's top is up on the body
    uv = np.stack([u, v], axis=1)[first] / tile
    return DisplayMesh(sim[first].astype(np.int64), uv.astype(np.float32), inverse.reshape(faces.shape))
