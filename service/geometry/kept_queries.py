"""Closest points kept for a fixed set of moving points, and asked ahead on a background thread.

The squeeze and the repair ask the same mesh about a garment's vertices round after round and move only a
few of them: ``KeptQueries`` answers the ones that did not move from memory (a query is a function of the
point alone). On the faces that may face the body (a fold's middle sheet) it takes the side from the
crossing parity of ``service.geometry.fold_side``: this module builds on both ``closest`` and
``fold_side``, so that neither imports the other.
"""

from __future__ import annotations

from concurrent.futures import Future

import numpy as np
from numba import njit

from service.geometry.closest import Closest, ClosestPoint
from service.geometry.fold_side import FoldSides
from service.process.threads import pool


class KeptQueries:
    """Closest points on one mesh for a fixed set of ``n`` moving points (a garment's vertices), kept
    between calls: a point that did not move gets its last answer (the query is a function of the
    point alone), so the repair's and the squeeze's rounds only ask for what they moved."""

    def __init__(self, mesh: ClosestPoint, n: int, reversed_faces: np.ndarray | None = None,
                 sides: FoldSides | None = None):  # fmt: skip
        self.mesh = mesh
        self.reversed = reversed_faces
        """(F,) bool or None: faces that may face the body (a fold's middle sheet). Without ``sides``, the
        signed distances and normals of the points closest to them are kept turned over."""
        self.sides = sides
        """``service.geometry.fold_side.FoldSides`` of ``mesh``, or None. Given, the points within its
        band whose closest face is one of ``reversed`` take their side from it: turned over where the
        winding disagrees, so that the normal points to the side the parity calls outside."""
        self.points = np.full((n, 3), np.nan)  # NaN: never asked
        self.signed = np.zeros(n)
        self.point = np.zeros((n, 3))
        self.normal = np.zeros((n, 3))
        self.rim = np.zeros(n, dtype=bool)

    def at(self, x: np.ndarray, ask: np.ndarray, split: bool = True):
        """(signed distance (K,), closest point (K, 3), face normal (K, 3), closest point on the mesh's
        rim (K,) bool) at the points ``ask (K,)`` of ``x (n, 3)``, querying only those that moved since
        they were last asked (``ClosestPoint.query``'s ``split``)."""
        ask = self._refresh(x, ask, split)
        return self.signed[ask], self.point[ask], self.normal[ask], self.rim[ask]

    def signed_at(self, x: np.ndarray, ask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``at``'s signed distances and rim flags alone (the squeeze reads no closest point or normal)."""
        ask = self._refresh(x, ask, True)
        return self.signed[ask], self.rim[ask]

    def _refresh(self, x: np.ndarray, ask: np.ndarray, split: bool) -> np.ndarray:
        """Query the points ``ask`` of ``x`` that moved since they were last asked; ``ask`` as int64."""
        ask = np.ascontiguousarray(ask, dtype=np.int64)
        stale = np.empty(len(ask), dtype=np.int64)
        stale = stale[: _moved(np.ascontiguousarray(x, dtype=np.float64), self.points, ask, stale)]
        if len(stale):
            self.store(x, stale, self.mesh.query(x[stale], split))
        return ask

    def store(self, x: np.ndarray, idx: np.ndarray, q: Closest) -> None:
        """Keep ``q``, the mesh's answer for the points ``idx (K,)`` of ``x (n, 3)`` (asked by the
        caller, e.g. in one batch with other point sets)."""
        self.points[idx] = x[idx]
        self.signed[idx], self.point[idx], self.normal[idx] = q.signed, q.point, q.normal
        self.rim[idx] = self.mesh.on_boundary(q)
        if self.reversed is not None:
            facing = self.reversed[q.face]
            if self.sides is not None:
                ask = np.flatnonzero(facing & (q.distance < self.sides.band))
                facing = np.zeros(len(idx), dtype=bool)
                facing[ask] = self.sides.inside(x[idx[ask]]) != (q.signed[ask] < 0)
            turned = idx[facing]
            self.signed[turned] *= -1
            self.normal[turned] *= -1


def ask_ahead(kept: KeptQueries, x: np.ndarray, ask: np.ndarray) -> Future:
    """Ask ``kept``'s mesh for the points ``ask (K,)`` of ``x (n, 3)`` on a background thread, before the
    caller needs them; the caller waits for the returned future before it reads ``kept`` (and leaves
    ``x`` unchanged until then). The answers are the ones ``kept.at`` gives on the caller's thread, bit
    for bit (a function of the point alone): only when they are computed changes. The world-space
    squeeze and repair ask ahead for the layers they reach two or more layers later, while the second
    core would otherwise wait on their numpy and Python work."""
    mesh = kept.mesh
    _ = mesh.topology, mesh.boxes, mesh.fn, mesh.pseudo  # built here: cached_property is not thread-safe
    return pool("ask ahead", 1).submit(kept.at, x, ask, False)


@njit(cache=True, nogil=True)
def _moved(x, kept, ask, out) -> int:
    """The points ``ask`` of ``x (n, 3)`` that differ from ``kept (n, 3)`` (NaN: never asked) into
    ``out``, in order; returns how many: ``ask[np.any(x[ask] != kept[ask], axis=1)]`` in one pass
    (the repair's and the squeeze's rounds ask about thousands of vertices of which few moved)."""
    m = 0
    for i in ask:
        if x[i, 0] != kept[i, 0] or x[i, 1] != kept[i, 1] or x[i, 2] != kept[i, 2]:
            out[m] = i
            m += 1
    return m
