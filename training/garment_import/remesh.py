"""A simulation mesh for a garment file too coarse or too fine for the drape; the file's mesh for display.

The drape, the explicit model and the fields are built for edges of about a centimetre
(``validate.EDGE_RANGE``): far coarser and the cloth cannot fold, far finer and an import costs hours.
Such a file's garment is remeshed isotropically to ``TARGET_EDGE`` (boundaries kept where they are, so
the openings stay), and the file's own mesh, with its UVs, becomes the display mesh riding on the
new simulation mesh (``service.pipeline.appearance.Embedding``): what the shop made is what the
outfit shows, moved by the cloth the service simulates.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from service.geometry.closest import ClosestPoint
from service.geometry.mesh import boundary_loops, edge_lengths
from service.pipeline.appearance import DisplayMesh, Embedding
from training.garment_import.read import GarmentFileError, SourceGarment

TARGET_EDGE = 0.012  # m: the procedural garments' edge length
SUBDIVIDE_ABOVE = 1.5  # x TARGET_EDGE: a coarser display mesh is subdivided to follow the cloth
MAX_OFFSET = 0.005  # m: a display vertex farther than this from the simulation mesh is not on it


def needs_remesh(garment: SourceGarment, edge_range: tuple[float, float]) -> float | None:
    """The garment's mean edge (m) when it lies outside ``edge_range``, else None."""
    mean_edge = float(edge_lengths(garment.vertices, garment.faces).mean())
    lo, hi = edge_range
    return None if lo <= mean_edge <= hi else mean_edge


def embed_display(garment: SourceGarment, vertices: np.ndarray, faces: np.ndarray) -> DisplayMesh:
    """The garment's display mesh (its file's mesh, subdivided where coarse; plain positions with zero
    UVs when it had none) embedded in the simulation mesh ``vertices (V, 3)``, ``faces (F, 3)`` at
    each display vertex's closest point."""
    display = garment.display
    if display is None:
        n = len(garment.vertices)
        display = DisplayMesh(np.arange(n), np.zeros((n, 2), np.float32), garment.faces.copy())
    points, uv, display_faces = garment.vertices[display.source], display.uv, display.faces
    if len(points):
        points, uv, display_faces = _subdivided(points, uv, display_faces, SUBDIVIDE_ABOVE * TARGET_EDGE)
    q = ClosestPoint.build(vertices, faces).query(points)
    embedding = Embedding.build(points, vertices, faces, q.face, q.bary)
    nearest = faces[q.face, np.argmax(q.bary, axis=1)]
    return DisplayMesh(nearest.astype(np.int64), uv.astype(np.float32), display_faces, embedding)


def _subdivided(points: np.ndarray, uv: np.ndarray, faces: np.ndarray, longest: float):
    """``points (D, 3)``, ``uv (D, 2)``, ``faces (F, 3)`` split 1-to-4 (UVs at edge midpoints, so the
    texture maps as before) until the mean edge is at most ``longest``: a coarse file's flat facets
    would otherwise cut through the cloth the simulation rounds under them."""
    from trimesh.remesh import subdivide

    while edge_lengths(points, faces).mean() > longest:
        points, faces, attributes = subdivide(points, faces, vertex_attributes={"uv": uv})
        uv = attributes["uv"]
    return points, uv, faces.astype(np.int64)


def remesh_for_simulation(path: Path | str, garment: SourceGarment, mean_edge: float,
                          target: float = TARGET_EDGE) -> tuple[SourceGarment, str]:  # fmt: skip
    """The garment on a simulation mesh of edges about ``target``, its display mesh embedded, and the
    note that says so; ``GarmentFileError`` if the remeshed surface loses an opening or leaves the
    file's mesh."""
    from training.garments.build import remesh  # pymeshlab: offline only

    vertices, faces = remesh(garment.vertices, garment.faces, target)
    before, after = len(boundary_loops(garment.faces)), len(boundary_loops(faces))
    if before != after:
        problem = f"remeshing it to {target * 1e3:.0f} mm edges changed its openings from {before} to {after}"
        raise GarmentFileError(path, problem, "Remesh it yourself to edges of about 12 mm.")
    display = embed_display(garment, vertices, faces)
    offset = float(np.linalg.norm(display.embedding.offset, axis=1).max()) if len(display.source) else 0.0
    if offset > MAX_OFFSET:
        problem = (f"its mesh is {offset * 1e3:.1f} mm from the remeshed simulation surface (cloth folded "
                   f"tighter than {target * 1e3:.0f} mm edges can follow)")  # fmt: skip
        raise GarmentFileError(path, problem, "Remesh it yourself to edges of about 12 mm.")
    kept = len(garment.vertices if garment.display is None else garment.display.source)
    note = (f"mean edge {mean_edge * 1e3:.1f} mm is too {'coarse' if mean_edge > target else 'fine'} for the "
            f"simulation: remeshed to {len(vertices)} vertices ({target * 1e3:.0f} mm edges); the file's "
            f"{kept}-vertex mesh is kept for display ({len(display.source)} vertices), at most "
            f"{offset * 1e3:.2f} mm off it")
    return replace(garment, vertices=vertices, faces=faces, display=display), note
