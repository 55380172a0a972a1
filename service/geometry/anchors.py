"""Where a garment's vertices sit on the body, and which of its faces face the body.

A garment's vertex is anchored to the body face its rest mesh is closest to on the mean body (every body
shares its faces): the squeeze walks hanging cloth to its anchor, and the repair and the measures read a
face as facing the body (a fold's middle sheet) against its corners' anchor normals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from service.geometry.closest import ClosestPoint
from service.geometry.mesh import face_normals


@dataclass(frozen=True)
class BodyAnchors:
    """Where each garment vertex sits on the body: a face of the body mesh and barycentric weights,
    from the garment's rest mesh on the mean body (every body shares its faces)."""

    face: np.ndarray  # (V,) int64
    bary: np.ndarray  # (V, 3)

    @classmethod
    def build(cls, rest: np.ndarray, mean_body: ClosestPoint) -> BodyAnchors:
        """Anchors of rest vertices ``(V, 3)`` at their closest points on the mean body."""
        q = mean_body.query(rest)
        return cls(q.face, q.bary)

    def on(self, body_vertices: np.ndarray, body_faces: np.ndarray) -> np.ndarray:
        """The anchors on a body of the same topology: ``(V, 3)`` points."""
        corners = body_vertices[body_faces[self.face]]  # (V, 3, 3)
        return np.einsum("vk,vkx->vx", self.bary, corners)

    def reversed_faces(self, vertices: np.ndarray, faces: np.ndarray, body_vertices: np.ndarray,
                       body_faces: np.ndarray, body_normals: np.ndarray | None = None,
                       ) -> np.ndarray:  # fmt: skip
        """``(F,)`` bool: faces of the garment ``vertices (V, 3)``, ``faces (F, 3)`` on this body whose
        normal points against the body's, summed over their corners' anchor faces: the middle sheet of a
        Z-fold, seen from above, says "inside" where a vertex is over it. A layer pushed out along it
        went into the body: a tank top over a jacket's chest fold, pushed back and forth between the
        two for 24 rounds. ``body_normals``: the body's unit face normals if the caller has them
        (``face_normals``). ``reversed_faces_reference`` bit for bit, the sums compiled
        (``_reversed_kernel``)."""
        if body_normals is None:
            body_normals = face_normals(body_vertices, body_faces)
        body_normal = np.ascontiguousarray(body_normals[self.face])  # (V, 3) at each anchor
        faces = np.ascontiguousarray(faces, dtype=np.int64)
        out = np.empty(len(faces), dtype=np.bool_)
        _reversed_kernel(face_normals(vertices, faces, normalize=False), body_normal, faces, out)
        return out

    def reversed_faces_reference(self, vertices: np.ndarray, faces: np.ndarray, body_vertices: np.ndarray,
                                 body_faces: np.ndarray) -> np.ndarray:  # fmt: skip
        """``reversed_faces`` in numpy."""
        body_normal = face_normals(body_vertices, body_faces)[self.face]  # (V, 3) at each anchor
        normal = face_normals(vertices, faces, normalize=False)
        return np.einsum("fx,fx->f", normal, body_normal[faces].sum(axis=1)) < 0


@njit(cache=True, nogil=True)
def _reversed_kernel(normal, body_normal, faces, out):
    """Per face: its normal against the sum of its corners' anchor normals (summed corner by corner, as
    numpy's sum over that axis; the dot product as einsum's, x and z first, then y) below 0."""
    for t in range(len(faces)):
        a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
        s0 = body_normal[a, 0] + body_normal[b, 0] + body_normal[c, 0]
        s1 = body_normal[a, 1] + body_normal[b, 1] + body_normal[c, 1]
        s2 = body_normal[a, 2] + body_normal[b, 2] + body_normal[c, 2]
        out[t] = (normal[t, 0] * s0 + normal[t, 2] * s2) + normal[t, 1] * s1 < 0
