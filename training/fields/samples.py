"""Ground truth for the neural fields (paper 3.1): f, h and their gradients at points around a surface.

Everything lives in canonical space, where the runtime untangles: a garment is its explicit model's
mesh X(beta) (so that the field is the implicit twin of the explicit model, paper 4.2, and any number
of shapes can be drawn), and the body is the mean body for every beta (the diffused displacement
maps the body of any shape onto it exactly).

- f: signed distance to the mesh, negative on the body side (sign of (x - p) . n at the closest
  point p, ``service.geometry.closest``); grad f = sign (x - p) / |x - p|, the face normal on the surface.
- h: the covariant field of ``training.fields.hrbf``; for the body a constant -SATURATION (the body
  is always active).

Points per shape (``sample_points``): the surface with normal offsets of a few mm and of 1.5 cm, the
shell around the body within the garment's reach (where other garments' vertices live), the
neighbourhood of every opening, and uniform points in the garment's padded bounding box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from service.geometry.closest import ClosestPoint
from service.geometry.mesh import face_normals
from training.fields.hrbf import SATURATION, Opening, build_openings, covariant_field

PAD = 0.1  # m around the garment's bounding box where fields are sampled and evaluated
MIX = {"surface": 0.45, "shell": 0.25, "openings": 0.15, "box": 0.15}
SURFACE_SIGMAS = (0.003, 0.015)  # m, normal offsets of the surface samples (half each)
SHELL = (-0.01, 0.08)  # m, normal offsets of the body-shell samples
OPENING_SIGMA = 0.03  # m
NEAR_SURFACE = 0.01  # m: held-out errors count points sampled this close to the surface
GROUND_TRUTH_VERSION = 2
"""Bump when the ground truth changes: cached training data carries it in its name."""


@dataclass
class FieldSamples:
    """Points with ground truth: x (P, 3), f (P,), grad_f (P, 3), h (P,), grad_h (P, 3), float64."""

    x: np.ndarray
    f: np.ndarray
    grad_f: np.ndarray
    h: np.ndarray
    grad_h: np.ndarray


def surface_points(
    vertices: np.ndarray, faces: np.ndarray, n: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """(points ``(n, 3)``, unit face normals ``(n, 3)``): uniform over the area of the mesh."""
    fn = face_normals(vertices, faces, normalize=False)
    area = 0.5 * np.linalg.norm(fn, axis=1)
    face = rng.choice(len(faces), size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u, v = np.where(flip, 1 - u, u), np.where(flip, 1 - v, v)
    tri = vertices[faces[face]]
    p = tri[:, 0] + u[:, None] * (tri[:, 1] - tri[:, 0]) + v[:, None] * (tri[:, 2] - tri[:, 0])
    return p, fn[face] / (2 * area[face])[:, None]


def signed_distance(closest: ClosestPoint, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(f ``(P,)``, grad f ``(P, 3)``) of the mesh behind ``closest`` at ``x (P, 3)``."""
    c = closest.query(x)
    diff = x - c.point
    sign = np.sign(c.signed)
    sign[sign == 0] = 1.0
    on = c.distance < 1e-9
    grad = np.where(on[:, None], c.normal, sign[:, None] * diff / np.where(on, 1.0, c.distance)[:, None])
    return c.signed, grad


def sample_points(
    vertices: np.ndarray,
    faces: np.ndarray,
    body_vertices: np.ndarray,
    body_faces: np.ndarray,
    openings_loops: dict[str, np.ndarray],
    n: int,
    rng: np.random.Generator,
) -> np.ndarray:
    """``(n, 3)`` query points around a surface ``vertices (V, 3)``, ``faces (F, 3)``."""
    counts = {k: int(round(v * n)) for k, v in MIX.items()}
    counts["surface"] += n - sum(counts.values())
    lo, hi = vertices.min(axis=0) - PAD, vertices.max(axis=0) + PAD
    p, nrm = surface_points(vertices, faces, counts["surface"], rng)
    sigma = np.where(rng.random(len(p)) < 0.5, *SURFACE_SIGMAS)
    parts = [p + (rng.normal(size=len(p)) * sigma)[:, None] * nrm]
    # Body shell inside the garment's box: draw extra and keep those in the box.
    bp, bn = surface_points(body_vertices, body_faces, 4 * counts["shell"], rng)
    shell = bp + rng.uniform(*SHELL, size=len(bp))[:, None] * bn
    inside = np.all((shell > lo) & (shell < hi), axis=1)
    parts.append(shell[inside][: counts["shell"]])
    loops = [np.asarray(loop) for loop in openings_loops.values()]
    if loops:
        ids = np.concatenate(loops)
        centre = vertices[rng.choice(ids, size=counts["openings"])]
        parts.append(centre + rng.normal(scale=OPENING_SIGMA, size=centre.shape))
    missing = n - sum(len(q) for q in parts)
    parts.append(rng.uniform(lo, hi, size=(missing, 3)))
    return np.concatenate(parts)


def ground_truth(
    x: np.ndarray, vertices: np.ndarray, faces: np.ndarray, openings: list[Opening] | None
) -> FieldSamples:
    """Fields of the surface at ``x (P, 3)``; ``openings`` None for the (closed, always active) body."""
    f, gf = signed_distance(ClosestPoint.build(vertices, faces), x)
    if openings is None:
        h, gh = np.full(len(x), -SATURATION), np.zeros_like(x)
    else:
        h, gh = covariant_field(openings, x)
    return FieldSamples(x, f, gf, h, gh)


def garment_samples(
    vertices: np.ndarray,
    faces: np.ndarray,
    loops: dict[str, np.ndarray] | None,
    body_vertices: np.ndarray,
    body_faces: np.ndarray,
    n: int,
    rng: np.random.Generator,
) -> FieldSamples:
    """n training points with ground truth for one shape of a garment (``loops`` None: the body)."""
    x = sample_points(vertices, faces, body_vertices, body_faces, loops or {}, n, rng)
    openings = None if loops is None else build_openings(vertices, faces, loops)
    return ground_truth(x, vertices, faces, openings)


def near_surface_samples(
    vertices: np.ndarray, faces: np.ndarray, loops: dict[str, np.ndarray] | None, n: int, rng
) -> FieldSamples:
    """n evaluation points within ``NEAR_SURFACE`` of the surface (uniform normal offsets)."""
    p, nrm = surface_points(vertices, faces, n, rng)
    x = p + rng.uniform(-NEAR_SURFACE, NEAR_SURFACE, size=n)[:, None] * nrm
    openings = None if loops is None else build_openings(vertices, faces, loops)
    return ground_truth(x, vertices, faces, openings)
