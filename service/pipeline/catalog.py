"""The garment catalog: rest meshes on the mean body, with named openings.

Files: ``models/garments/catalog.json`` (ids, names, categories, layer ranks, file names) and
one ``<id>.npz`` per garment with ``vertices (V, 3) float32`` (metres, Anny frame: Z up, body
facing -Y), ``faces (F, 3) int32`` (normals away from the body) and, per opening ``name``,
``opening_<name> (L,) int32``: the boundary loop's vertex indices in order. A garment with a look
also has ``display_source (D,) int32``, ``display_uv (D, 2) float32`` and ``display_faces (F, 3) int32``
(``service.pipeline.appearance.DisplayMesh``), and its catalog entry a ``material``: base colour,
roughness and texture files (PNG, beside the npz) by slot.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Literal

import numpy as np

from service.geometry.mesh_topology import frozen
from service.pipeline.appearance import DisplayMesh, Embedding, Material
from service.process.manifest import verify_manifest
from service.process.paths import models_dir

Category = Literal["top", "bottom", "dress"]
Origin = Literal["bundled", "imported"]


@dataclass(frozen=True)
class Garment:
    """One catalog garment in its rest shape on the mean body.

    vertices: (V, 3) float64; faces: (F, 3) int64; openings: name -> (L,) int64 loop; display and
    material: how it looks (None: a flat colour, no UVs).

    layer_rank: how near the body the garment is worn by default, over the whole catalog (every
    category, imports included): lower is nearer. A stack whose ranks go up outwards is worn the usual
    way (bundled: tank top 1 tucked into the bottoms 2, the T-shirt 3, long sleeve 4 and jacket 5 over
    them); a garment over one of a lower rank is worn against it, and garments of equal rank have no
    usual order between them (a bottom in another): either is against it, which
    ``collisions.squeeze.asks_segment_test`` reads. Ranks only order: they need not be contiguous, and
    nothing else is read from them (what a garment does, it holds the legs apart, it covers the chest,
    comes from its geometry: ``collisions.traits``; ``category`` is the shop's label).
    """

    id: str
    name: str
    category: Category
    layer_rank: int
    vertices: np.ndarray
    faces: np.ndarray
    openings: dict[str, np.ndarray] = field(default_factory=dict)
    display: DisplayMesh | None = None
    material: Material | None = None
    origin: Origin = "bundled"

    def summary(self) -> dict:
        return {
            "id": self.id,
            "name": self.name,
            "category": self.category,
            "layer_rank": self.layer_rank,
            "vertices": int(len(self.vertices)),
            "faces": int(len(self.faces)),
            "openings": sorted(self.openings),
            "material": None if self.material is None else self.material.summary(),
            "origin": self.origin,
        }

    def catalog_entry(self) -> dict:
        """This garment's entry in ``catalog.json`` (with ``save_garment``'s file names)."""
        entry = {"id": self.id, "name": self.name, "category": self.category, "layer_rank": self.layer_rank,
                 "file": f"{self.id}.npz"}  # fmt: skip
        if self.material is not None:
            m = self.material
            entry["material"] = {"base_color": list(m.base_color), "roughness": m.roughness,
                                 "textures": dict(sorted(m.texture_files.items()))}  # fmt: skip
        return entry


def save_garment(directory: Path, garment: Garment) -> Path:
    """Write ``<id>.npz`` (float32 vertices, int32 indices) and the material's textures."""
    directory.mkdir(parents=True, exist_ok=True)
    arrays = {
        "vertices": garment.vertices.astype(np.float32),
        "faces": garment.faces.astype(np.int32),
    }
    arrays.update({f"opening_{k}": v.astype(np.int32) for k, v in garment.openings.items()})
    if garment.display is not None:
        garment.display.check(len(garment.vertices), garment.faces)
        arrays |= {"display_source": garment.display.source.astype(np.int32),
                   "display_uv": garment.display.uv.astype(np.float32),
                   "display_faces": garment.display.faces.astype(np.int32)}  # fmt: skip
        if (e := garment.display.embedding) is not None:
            arrays |= {"display_face": e.face.astype(np.int32), "display_bary": e.bary.astype(np.float32),
                       "display_offset": e.offset.astype(np.float32)}  # fmt: skip
    if garment.material is not None:
        for slot, png in garment.material.textures.items():
            (directory / garment.material.texture_files[slot]).write_bytes(png)
    path = directory / f"{garment.id}.npz"
    np.savez_compressed(path, **arrays)
    return path


def load_garment(directory: Path, entry: dict, origin: Origin = "bundled") -> Garment:
    with np.load(directory / entry["file"]) as data:
        prefix = "opening_"
        openings = {k[len(prefix) :]: data[k].astype(np.int64) for k in data.files if k.startswith(prefix)}
        display = None
        if "display_source" in data.files:
            embedding = None
            if "display_face" in data.files:
                embedding = Embedding(data["display_face"].astype(np.int64), data["display_bary"],
                                      data["display_offset"])  # fmt: skip
            display = DisplayMesh(data["display_source"].astype(np.int64), data["display_uv"],
                                  data["display_faces"].astype(np.int64), embedding)  # fmt: skip
            display.check(len(data["vertices"]), data["faces"].astype(np.int64))
        return Garment(
            id=entry["id"],
            name=entry["name"],
            category=entry["category"],
            layer_rank=int(entry["layer_rank"]),
            vertices=data["vertices"].astype(np.float64),
            faces=frozen(np.ascontiguousarray(data["faces"], dtype=np.int64)),
            openings=openings,
            display=display,
            material=_load_material(directory, entry.get("material")),
            origin=origin,
        )


def _load_material(directory: Path, spec: dict | None) -> Material | None:
    if spec is None:
        return None
    files = dict(spec.get("textures", {}))
    return Material(
        base_color=tuple(float(c) for c in spec["base_color"]),
        roughness=float(spec.get("roughness", 0.9)),
        textures={slot: (directory / name).read_bytes() for slot, name in files.items()},
        texture_files=files,
    )


@lru_cache(maxsize=16)
def load_catalog(directory: Path | None = None, origin: Origin = "bundled") -> dict[str, Garment]:
    """All garments by id, in the order of ``catalog.json`` (not by ``layer_rank``)."""
    directory = Path(directory) if directory is not None else models_dir() / "garments"
    index = json.loads((directory / "catalog.json").read_text())
    return {e["id"]: load_garment(directory, e, origin) for e in index["garments"]}


def imported_garment_dirs(garments_dir: Path | None) -> list[Path]:
    """The published imports in ``garments_dir`` (``<id>/`` with a manifest), by id; none for None.
    Staging work (``.staging/``) and anything without a manifest is not a garment yet."""
    if garments_dir is None or not Path(garments_dir).is_dir():
        return []
    published = (p for p in Path(garments_dir).iterdir() if p.is_dir() and not p.name.startswith("."))
    return sorted(p for p in published if (p / "manifest.json").is_file())


def verified_imports(garments_dir: Path | None) -> tuple[list[Path], dict[str, list[str]]]:
    """(imports whose files match their manifest, {id: problems} of those that do not)."""
    good, bad = [], {}
    for directory in imported_garment_dirs(garments_dir):
        problems = verify_manifest(directory)
        if problems:
            bad[directory.name] = problems
        else:
            good.append(directory)
    return good, bad


def full_catalog(bundled_dir: Path | None, garments_dir: Path | None) -> dict[str, Garment]:
    """The bundled catalog, then every verified import's garments (an id already taken is skipped)."""
    catalog = dict(load_catalog(bundled_dir))
    for directory in verified_imports(garments_dir)[0]:
        for gid, garment in load_catalog(directory / "garments", origin="imported").items():
            catalog.setdefault(gid, garment)
    return catalog
