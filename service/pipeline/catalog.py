"""The garment catalog: rest meshes on the mean body, with named openings.

Files: ``models/garments/catalog.json`` (ids, names, categories, layer ranks, file names) and
one ``<id>.npz`` per garment with ``vertices (V, 3) float32`` (metres, Anny frame: Z up, body
facing -Y), ``faces (F, 3) int32`` (normals away from the body) and, per opening ``name``,
``opening_<name> (L,) int32``: the boundary loop's vertex indices in order.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Literal

import numpy as np

from service.process.paths import models_dir

Category = Literal["top", "bottom"]


@dataclass(frozen=True)
class Garment:
    """One catalog garment in its rest shape on the mean body.

    vertices: (V, 3) float64; faces: (F, 3) int64; openings: name -> (L,) int64 loop.
    """

    id: str
    name: str
    category: Category
    layer_rank: int
    vertices: np.ndarray
    faces: np.ndarray
    openings: dict[str, np.ndarray] = field(default_factory=dict)

    def summary(self) -> dict:
        return {
            "id": self.id,
            "name": self.name,
            "category": self.category,
            "layer_rank": self.layer_rank,
            "vertices": int(len(self.vertices)),
            "faces": int(len(self.faces)),
            "openings": sorted(self.openings),
        }


def save_garment(directory: Path, garment: Garment) -> Path:
    """Write ``<id>.npz`` (float32 vertices, int32 indices)."""
    directory.mkdir(parents=True, exist_ok=True)
    arrays = {
        "vertices": garment.vertices.astype(np.float32),
        "faces": garment.faces.astype(np.int32),
    }
    arrays.update({f"opening_{k}": v.astype(np.int32) for k, v in garment.openings.items()})
    path = directory / f"{garment.id}.npz"
    np.savez_compressed(path, **arrays)
    return path


def load_garment(directory: Path, entry: dict) -> Garment:
    with np.load(directory / entry["file"]) as data:
        prefix = "opening_"
        openings = {k[len(prefix) :]: data[k].astype(np.int64) for k in data.files if k.startswith(prefix)}
        return Garment(
            id=entry["id"],
            name=entry["name"],
            category=entry["category"],
            layer_rank=int(entry["layer_rank"]),
            vertices=data["vertices"].astype(np.float64),
            faces=data["faces"].astype(np.int64),
            openings=openings,
        )


@lru_cache(maxsize=4)
def load_catalog(directory: Path | None = None) -> dict[str, Garment]:
    """All garments by id, in catalog order (inner to outer default ranks)."""
    directory = Path(directory) if directory is not None else models_dir() / "garments"
    index = json.loads((directory / "catalog.json").read_text())
    return {e["id"]: load_garment(directory, e) for e in index["garments"]}
