"""Read a shop's garment file (OBJ + MTL + textures, or glTF/GLB) into the avatar's frame.

A design tool writes the garment where it draped it: on the avatar of ``ulnef avatar``, Y up, facing
+Z, feet on y = 0, in the unit the avatar was written in. This turns it back into Anny's frame
(metres, Z up, facing -Y, the mean body where ``BodyModel`` has it), welds the vertices a UV seam
split (one simulation vertex per point of the cloth) and keeps the file's mesh, with its UVs, as the
display mesh over the welded one. The material keeps the base colour factor, the base colour
texture and the normal map, re-encoded as PNG.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from service.pipeline.appearance import DisplayMesh, Material
from service.pipeline.avatar import SCALE
from service.pipeline.gltf import ANNY_TO_GLTF

WELD = 1e-6  # m: positions closer than this are one point of the cloth


class GarmentFileError(ValueError):
    """A garment file the import cannot use: ``problem`` says what, ``fix`` what to do about it."""

    def __init__(self, path: Path | str, problem: str, fix: str):
        super().__init__(f"{path}: {problem}. {fix}")
        self.path, self.problem, self.fix = str(path), problem, fix


@dataclass(frozen=True)
class SourceGarment:
    """vertices (V, 3) float64 m in Anny's frame (welded), faces (F, 3) int64 over them, the display
    mesh (the file's vertices with their UVs; None without UVs) and the material."""

    vertices: np.ndarray
    faces: np.ndarray
    display: DisplayMesh | None
    material: Material


def _png(image) -> bytes:
    """A PIL image as PNG bytes (RGB, or RGBA when it has transparency)."""
    out = io.BytesIO()
    mode = "RGBA" if image.mode in ("RGBA", "LA", "P") else "RGB"
    image.convert(mode).save(out, format="PNG")
    return out.getvalue()


def _material(visual, stem: str) -> Material:
    """Base colour factor and textures of a trimesh visual (PBR from glTF, simple from OBJ's MTL)."""
    material = getattr(visual, "material", None)
    color, textures = (0.6, 0.6, 0.6, 1.0), {}
    if material is None:
        return Material(color)
    if hasattr(material, "to_pbr"):
        material = material.to_pbr()
    factor = getattr(material, "baseColorFactor", None)
    if factor is not None:
        factor = np.asarray(factor, dtype=np.float64).reshape(-1)
        color = tuple(float(c) for c in (factor / 255.0 if factor.max() > 1.0 else factor))
        color = (*color[:3], color[3] if len(color) > 3 else 1.0)
    if getattr(material, "baseColorTexture", None) is not None:
        textures["base_color"] = _png(material.baseColorTexture)
    if getattr(material, "normalTexture", None) is not None:
        textures["normal"] = _png(material.normalTexture)
    files = {slot: f"{stem}.{'base' if slot == 'base_color' else 'normal'}.png" for slot in textures}
    roughness = getattr(material, "roughnessFactor", None)
    return Material(color, 0.9 if roughness is None else float(roughness), textures, files)


def load_mesh(path: Path):
    """The one triangle mesh in ``path`` (a trimesh.Trimesh, node transforms applied)."""
    import trimesh

    suffix = path.suffix.lower()
    if suffix not in (".obj", ".glb", ".gltf"):
        raise GarmentFileError(path, f"{suffix or 'no extension'} is not a garment format",
                               "Export it as OBJ (with its MTL and textures) or glTF/GLB.")  # fmt: skip
    if not path.is_file():
        raise GarmentFileError(path, "no such file", "Check the path.")
    try:
        loaded = trimesh.load(path, process=False)  # UV seams split vertices
    except Exception as e:  # trimesh raises many kinds for a broken file
        raise GarmentFileError(path, f"cannot be read ({type(e).__name__}: {e})",
                               "Re-export it from the design tool.") from None  # fmt: skip
    if isinstance(loaded, trimesh.Scene):
        meshes = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
        if not meshes:
            raise GarmentFileError(path, "holds no triangle mesh", "Export the garment's mesh.")
        if len(meshes) > 1:
            raise GarmentFileError(path, f"holds {len(meshes)} meshes",
                                   "Export the garment as one mesh (join its pieces).")  # fmt: skip
        loaded = meshes[0]
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise GarmentFileError(path, "holds no triangle mesh", "Export the garment's mesh.")
    return loaded


def read_garment(path: Path | str, units: str, floor: float, garment_id: str) -> SourceGarment:
    """The garment of ``path`` in Anny's frame; ``units`` of the file (m, cm, mm), ``floor`` the
    mean body's lowest z in Anny's frame (the avatar stands on y = 0); textures named by the id."""
    path = Path(path)
    mesh = load_mesh(path)
    positions = np.asarray(mesh.vertices, dtype=np.float64) / SCALE[units]
    anny = positions @ ANNY_TO_GLTF + [0.0, 0.0, floor]  # the inverse rotation: ANNY_TO_GLTF is orthonormal
    display_faces = np.asarray(mesh.faces, dtype=np.int64)
    if not np.all(np.isfinite(anny)):
        raise GarmentFileError(path, "has non-finite vertex positions", "Re-export it from the design tool.")
    keys = np.round(anny / WELD).astype(np.int64)
    _, first, source = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    source = source.reshape(-1)
    vertices, faces = anny[first], source[display_faces]
    uv = getattr(mesh.visual, "uv", None)
    display = None
    if uv is not None and len(uv) == len(anny):
        # trimesh reports v up (origin bottom left, as OBJ); glTF's runs down.
        uv = np.asarray(uv, dtype=np.float64)
        flipped = np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1).astype(np.float32)
        display = DisplayMesh(source.astype(np.int64), flipped, display_faces)
    return SourceGarment(vertices, faces, display, _material(mesh.visual, garment_id))
