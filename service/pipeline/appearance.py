"""How a garment looks: its display mesh (UVs, where seams split vertices) and its material.

The simulation mesh (``Garment.vertices``, ``faces``) is welded: one vertex per point of the cloth,
which the drape, the fields and the fit need. A UV seam gives one point two texture coordinates, so
what a client draws is a second mesh over the same triangles: display vertex d is simulation vertex
``source[d]`` with texture coordinate ``uv[d]``, and display face k is simulation face k
(``source[faces] == simulation faces``). The fit keeps the topology, so a fitted garment's display
mesh is ``fitted[source]``: the shop's texture follows the cloth.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
TextureSlot = str  # "base_color" or "normal"
TEXTURE_SLOTS: tuple[TextureSlot, ...] = ("base_color", "normal")


@dataclass(frozen=True)
class DisplayMesh:
    """source: (D,) int64 simulation vertex per display vertex; uv: (D, 2) float32 (glTF convention:
    origin at the image's top left, v down; values outside [0, 1] repeat); faces: (F, 3) int64."""

    source: np.ndarray
    uv: np.ndarray
    faces: np.ndarray

    def check(self, n_vertices: int, faces: np.ndarray) -> None:
        """Raise ValueError unless this maps onto a simulation mesh of ``n_vertices``, ``faces (F, 3)``."""
        d = len(self.source)
        if self.source.shape != (d,) or self.uv.shape != (d, 2) or self.faces.shape != faces.shape:
            raise ValueError(
                f"display mesh: source {self.source.shape}, uv {self.uv.shape}, faces {self.faces.shape} "
                f"do not fit {n_vertices} vertices and faces {faces.shape}"
            )
        if d and (self.source.min() < 0 or self.source.max() >= n_vertices):
            raise ValueError(f"display mesh: source indices outside 0..{n_vertices - 1}")
        if len(self.faces) and (self.faces.min() < 0 or self.faces.max() >= d):
            raise ValueError(f"display mesh: face indices outside 0..{d - 1}")
        if not np.array_equal(self.source[self.faces], faces):
            raise ValueError("display mesh: its faces are not the simulation faces, face by face")
        if not np.all(np.isfinite(self.uv)):
            raise ValueError("display mesh: uv must be finite")


@dataclass(frozen=True)
class Material:
    """glTF metallic-roughness material: base colour factor RGBA in [0, 1], roughness, and PNG
    textures by slot (``TEXTURE_SLOTS``), each with the file name it came from."""

    base_color: tuple[float, float, float, float] = (0.6, 0.6, 0.6, 1.0)
    roughness: float = 0.9
    textures: dict[TextureSlot, bytes] = field(default_factory=dict)
    texture_files: dict[TextureSlot, str] = field(default_factory=dict)

    def __post_init__(self):
        if len(self.base_color) != 4 or not all(0.0 <= c <= 1.0 for c in self.base_color):
            raise ValueError(f"material: base_color must be 4 values in [0, 1], got {self.base_color}")
        for slot, png in self.textures.items():
            if slot not in TEXTURE_SLOTS:
                raise ValueError(f"material: unknown texture slot {slot!r} (one of {TEXTURE_SLOTS})")
            if not png.startswith(PNG_MAGIC):
                raise ValueError(f"material: the {slot} texture is not a PNG")

    def summary(self) -> dict:
        """What ``GET /v1/garments`` says of it (texture file names, not bytes)."""
        return {
            "base_color": [round(float(c), 4) for c in self.base_color],
            "roughness": round(float(self.roughness), 4),
            "textures": dict(sorted(self.texture_files.items())),
        }
