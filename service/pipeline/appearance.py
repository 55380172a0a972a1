"""How a garment looks: its display mesh (UVs, where seams split vertices) and its material.

The simulation mesh (``Garment.vertices``, ``faces``) is welded: one vertex per point of the cloth,
which the drape, the fields and the fit need. A UV seam gives one point two texture coordinates, so
what a client draws is a second mesh over the same triangles: display vertex d is simulation vertex
``source[d]`` with texture coordinate ``uv[d]``, and display face k is simulation face k
(``source[faces] == simulation faces``). The fit keeps the topology, so a fitted garment's display
mesh is ``fitted[source]``: the shop's texture follows the cloth.

A garment whose file was too coarse or too fine for the simulation is remeshed for it, and its file's
mesh kept for display: then the display mesh rides on the simulation mesh (``Embedding``), each
display vertex at fixed barycentric coordinates of one simulation triangle plus a fixed offset in that
triangle's frame, so the fine folds of the file move with the cloth the fit moves.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
TextureSlot = str  # "base_color" or "normal"
TEXTURE_SLOTS: tuple[TextureSlot, ...] = ("base_color", "normal")


def face_frames(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3, 3) orthonormal frame per triangle, rows: first edge's direction, normal x it, normal."""
    tri = vertices[faces]
    e = tri[:, 1] - tri[:, 0]
    n = np.cross(e, tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    e /= np.maximum(np.linalg.norm(e, axis=1, keepdims=True), 1e-300)
    return np.stack([e, np.cross(n, e), n], axis=1)


@dataclass(frozen=True)
class Embedding:
    """Display vertices riding on a simulation mesh they are not vertices of: display vertex d is at
    barycentric coordinates ``bary[d]`` (D, 3) of simulation face ``face[d]`` (D,) plus ``offset[d]``
    (D, 3) m in that face's frame (``face_frames``)."""

    face: np.ndarray
    bary: np.ndarray
    offset: np.ndarray

    @classmethod
    def build(
        cls, points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, face: np.ndarray, bary: np.ndarray
    ) -> Embedding:
        """The embedding that ``place``s ``points (D, 3)`` where they are over ``vertices``, ``faces``,
        given the face and barycentric coordinates each is attached to (its closest point)."""  # fmt: skip
        on = np.einsum("dk,dkx->dx", bary, vertices[faces[face]])
        offset = np.einsum("dij,dj->di", face_frames(vertices, faces)[face], points - on)
        return cls(face.astype(np.int64), bary.astype(np.float32), offset.astype(np.float32))

    def place(self, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray):
        """Display positions (D, 3) over the simulation mesh ``vertices (V, 3)``, ``faces (F, 3)``, and
        their normals (D, 3): the simulation's vertex ``normals (V, 3)`` interpolated, renormalised."""
        corners = faces[self.face]
        bary = self.bary.astype(np.float64)
        on = np.einsum("dk,dkx->dx", bary, vertices[corners])
        positions = on + np.einsum("dji,dj->di", face_frames(vertices, faces)[self.face], self.offset)
        n = np.einsum("dk,dkx->dx", bary, normals[corners])
        return positions, n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


@dataclass(frozen=True)
class DisplayMesh:
    """source: (D,) int64 simulation vertex per display vertex (with an ``embedding``: the simulation
    vertex it follows most); uv: (D, 2) float32 (glTF convention: origin at the image's top left, v
    down; values outside [0, 1] repeat); faces: (F', 3) int64, the simulation faces face by face
    unless there is an embedding."""

    source: np.ndarray
    uv: np.ndarray
    faces: np.ndarray
    embedding: Embedding | None = None

    def check(self, n_vertices: int, faces: np.ndarray) -> None:
        """Raise ValueError unless this maps onto a simulation mesh of ``n_vertices``, ``faces (F, 3)``."""
        d, e = len(self.source), self.embedding
        shapes_fit = self.source.shape == (d,) and self.uv.shape == (d, 2) and self.faces.shape[1:] == (3,)
        if not shapes_fit or (e is None and self.faces.shape != faces.shape):
            raise ValueError(
                f"display mesh: source {self.source.shape}, uv {self.uv.shape}, faces {self.faces.shape} "
                f"do not fit {n_vertices} vertices and faces {faces.shape}"
            )
        if d and (self.source.min() < 0 or self.source.max() >= n_vertices):
            raise ValueError(f"display mesh: source indices outside 0..{n_vertices - 1}")
        if len(self.faces) and (self.faces.min() < 0 or self.faces.max() >= d):
            raise ValueError(f"display mesh: face indices outside 0..{d - 1}")
        if e is None and not np.array_equal(self.source[self.faces], faces):
            raise ValueError("display mesh: its faces are not the simulation faces, face by face")
        if e is not None:
            if e.face.shape != (d,) or e.bary.shape != (d, 3) or e.offset.shape != (d, 3):
                raise ValueError(f"display mesh: embedding face {e.face.shape}, bary {e.bary.shape}, "
                                 f"offset {e.offset.shape} do not fit {d} display vertices")  # fmt: skip
            if d and (e.face.min() < 0 or e.face.max() >= len(faces)):
                raise ValueError(f"display mesh: embedding faces outside 0..{len(faces) - 1}")
            if not (np.all(np.isfinite(e.bary)) and np.all(np.isfinite(e.offset))):
                raise ValueError("display mesh: embedding must be finite")
        if not np.all(np.isfinite(self.uv)):
            raise ValueError("display mesh: uv must be finite")

    def place(self, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray):
        """Display positions (D, 3) and normals (D, 3) of the simulation mesh ``vertices (V, 3)``,
        ``faces (F, 3)`` with vertex ``normals (V, 3)``: shared normals keep UV seams invisible."""
        if self.embedding is None:
            return vertices[self.source], normals[self.source]
        return self.embedding.place(vertices, faces, normals)

    def flipped(self) -> DisplayMesh:
        """The same mesh wound the other way, for a simulation mesh whose faces were flipped too."""
        if self.embedding is not None:  # flipping changes the face frames the offsets are in
            raise ValueError("display mesh: flip the garment before embedding its display mesh")
        return DisplayMesh(self.source, self.uv, self.faces[:, ::-1].copy())


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
