"""Check an imported garment before hours of simulation go into it, and say exactly what is wrong.

Refused (``GarmentFileError``, with the fix): several pieces, non-manifold edges, degenerate or
duplicate faces, inconsistent winding, no boundary loop (a closed surface cannot be put on), a
garment not on the avatar (most of it far away: wrong frame or units), cloth deep inside the body.
Fixed and reported (notes): the whole garment wound inwards (flipped), cloth a little inside the body
(pushed out to ``CLEARANCE``); a mesh outside ``EDGE_RANGE`` is remeshed by ``remesh``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from service.geometry.closest import ClosestPoint
from service.geometry.mesh import connected_components, vertex_normals
from service.pipeline.body import DEFAULT_BETA, BodyModel
from training.garment_import.read import GarmentFileError, SourceGarment

CLEARANCE = 0.004  # m: no vertex closer to the mean body than this (as the procedural garments)
SHALLOW = 0.010  # m: deeper inside the body than this is refused, not pushed out
FAR = 0.15  # m from the body
FAR_SHARE = 0.5  # of the vertices that far away: not on the avatar
EDGE_RANGE = (0.004, 0.03)  # m: mean edge length the simulation is built for (~1.2 cm)


def push_out(vertices: np.ndarray, body: ClosestPoint, rounds: int = 5) -> np.ndarray:
    """``vertices (V, 3)`` with every one closer to the body than ``CLEARANCE`` moved out along its
    closest face's normal, again where a move near an edge or corner left it short (``rounds`` at
    most); the result is at least ``CLEARANCE - 1e-6`` from the body."""
    out = vertices.copy()
    for _ in range(rounds):
        q = body.query(out)
        short = q.signed < CLEARANCE - 1e-6
        if not short.any():
            break
        out[short] = q.point[short] + CLEARANCE * q.normal[short]
    return out


def _where(body: BodyModel, points: np.ndarray) -> str:
    """The body parts nearest to ``points (N, 3)`` on the mean body, most common first."""
    mean = body.vertices(np.asarray(DEFAULT_BETA))
    regions = body.regions[cKDTree(mean).query(points)[1]]
    names, counts = np.unique(regions, return_counts=True)
    return ", ".join(body.region_names[n] for n in names[np.argsort(-counts)][:3])


def _flip(garment: SourceGarment) -> SourceGarment:
    display = None if garment.display is None else garment.display.flipped()
    return replace(garment, faces=garment.faces[:, ::-1].copy(), display=display)


def _at(points: np.ndarray) -> str:
    return f"{np.round(points.mean(0), 3).tolist()} m"


def check_topology(path, garment: SourceGarment) -> None:
    """Raise ``GarmentFileError`` for what no fix can make right."""
    v, f = garment.vertices, garment.faces
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])
    area = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1) / 2
    degenerate = repeated | (area < 1e-10)
    if degenerate.any():
        problem = f"{int(degenerate.sum())} degenerate faces (zero area), e.g. at {_at(v[f[degenerate][0]])}"
        raise GarmentFileError(path, problem, "Remove or merge them in the design tool.")
    _, counts = np.unique(np.sort(f, axis=1), axis=0, return_counts=True)
    if (counts > 1).any():
        problem = f"{int((counts - 1).sum())} duplicate faces (the same three vertices twice)"
        raise GarmentFileError(path, problem, "Remove the doubled faces.")
    pieces = np.bincount(connected_components(f, len(v))[np.unique(f)])
    sizes = sorted(pieces[pieces > 0].tolist(), reverse=True)
    if len(sizes) > 1:
        problem = f"{len(sizes)} separate pieces ({', '.join(map(str, sizes[:5]))} vertices)"
        fix = "Sew the pieces together or delete the stray ones: a garment is one piece of cloth."
        raise GarmentFileError(path, problem, fix)
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    undirected, uses = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    if (uses > 2).any():
        problem = (f"{int((uses > 2).sum())} non-manifold edges (shared by more than two faces), e.g. at "
                   f"{_at(v[undirected[uses > 2][0]])}")  # fmt: skip
        raise GarmentFileError(path, problem, "Split or remove the extra faces there.")
    _, same_way = np.unique(directed, axis=0, return_counts=True)
    if (same_way > 1).any():
        problem = f"{int((same_way > 1).sum())} edges where neighbouring faces are wound opposite ways"
        raise GarmentFileError(path, problem, "Recalculate the normals consistently, pointing outside.")
    if not (uses == 1).any():
        fix = "A garment needs openings (neck, sleeves, waist...): cut them."
        raise GarmentFileError(path, "a closed surface without openings", fix)


def fit_to_body(path, garment: SourceGarment, body: BodyModel) -> tuple[SourceGarment, list[str]]:
    """The garment outward-wound and clear of the mean body, and notes of what was changed."""
    notes = []
    mean = body.vertices(np.asarray(DEFAULT_BETA))
    closest = ClosestPoint.build(mean, body.faces)
    q = closest.query(garment.vertices)
    far = q.distance > FAR
    if far.mean() > FAR_SHARE:
        problem = f"{100 * far.mean():.0f} % of it is more than {FAR * 100:.0f} cm from the avatar"
        fix = ("Drape it on the avatar of `ulnef avatar` and export it in the avatar's frame; pass --units "
               "as the file was written (m, cm, mm).")  # fmt: skip
        raise GarmentFileError(path, problem, fix)
    normals = vertex_normals(garment.vertices, garment.faces)
    if np.mean(np.einsum("nd,nd->n", normals, garment.vertices - q.point) < 0) > 0.5:
        garment = _flip(garment)
        notes.append("faces were wound towards the body: flipped so that normals point outwards")
    deep = q.signed < -SHALLOW
    if deep.any():
        problem = (f"{int(deep.sum())} vertices are more than {SHALLOW * 1e3:.0f} mm inside the avatar "
                   f"(deepest {-q.signed.min() * 1e3:.0f} mm, at the {_where(body, garment.vertices[deep])})")
        raise GarmentFileError(path, problem, "Drape it again so that the cloth rests on the avatar.")
    inside = q.signed < CLEARANCE
    if inside.any():
        moved = push_out(garment.vertices, closest)
        depth = max(0.0, -q.signed.min()) * 1e3
        where = _where(body, garment.vertices[inside])
        notes.append(f"{int(inside.sum())} vertices closer than {CLEARANCE * 1e3:.0f} mm to the body (at "
                     f"most {depth:.1f} mm inside) pushed out, at the {where}")
        garment = replace(garment, vertices=moved)
    return garment, notes
