"""Which garment orders cloth can take, decided from the garments before the pipeline runs (issue 21).

Everything is read off horizontal slices (every ``CollisionSettings.slice_step``, Z up) of the rest meshes
on the mean body (catalog templates, bundled or imported: the same for every body shape, since each
garment is graded to the body it is worn on). At each level the body's cross-section is a set of closed
loops: the body *parts* there (torso, arms, legs). A garment's closed loop at that level *wraps* the parts
whose centres it encloses. Two rules:

1. **Topology.** Where the inner garment wraps parts in one loop (a skirt around both legs) that the
   outer garment's loops hold apart (pants, one loop per leg), the outer garment would have to pass
   between the parts through the inner one's cloth. No cloth does that, so the order is refused when
   this holds over more than ``join_tolerance`` of height (a crotch seam or an armhole that hangs a
   little lower than the other garment's is pushed up instead).
2. **Girth.** Where the outer garment wraps the inner one, its perimeter stretched by
   ``stretch_limit`` must hold the inner one pressed onto the body: the convex hull of the body
   parts it wraps, plus ``margin`` per layer between (a 2 mm clearance all round, as the repair
   keeps). Garments draped on this body always pass; a skin-tight garment cut smaller than the body
   (compression wear) over another one does not.

``refusals(profiles, ids)`` returns a ``Refusal`` (garments and reason) for every ordered pair of the
stack that fails; the service answers 422 with them. Slices are numpy only: a plane-triangle pass, loops
joined by the mesh edges they cross, point-in-loop by ray parity.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from service.pipeline.collisions.settings import SETTINGS


@dataclass(frozen=True)
class Loop:
    """One closed loop of a slice: its perimeter (m) and the body parts (indices at its level) inside."""

    perimeter: float
    parts: frozenset[int]


@dataclass(frozen=True)
class BodySlices:
    """The body's parts per level: ``levels (L,)`` heights, and per level the parts' centres
    ``(P, 2)``, hull perimeters ``(P,)`` and names (``torso``, ``arm``, ``leg``)."""

    levels: np.ndarray
    centres: list[np.ndarray]
    hulls: list[list[np.ndarray]]
    names: list[list[str]]

    @classmethod
    def build(cls, vertices: np.ndarray, faces: np.ndarray) -> BodySlices:
        lo, hi = vertices[:, 2].min(), vertices[:, 2].max()
        levels = np.arange(lo + SETTINGS.slice_step / 2, hi, SETTINGS.slice_step)
        centres, hulls, names = [], [], []
        crotch = None
        for z in levels[::-1]:  # from the head down: the torso's loop ends at the crotch
            loops = slice_loops(vertices, faces, z)
            loops = [lp for lp in loops if lp.closed and lp.perimeter >= SETTINGS.min_part]
            c = np.array([lp.centre for lp in loops]).reshape(-1, 2)
            centres.append(c)
            hulls.append([lp.points for lp in loops])
            mid = [lp.contains(np.array([[0.0, lp.centre[1]]]))[0] for lp in loops]
            if crotch is None and z < lo + 0.6 * (hi - lo) and not any(mid):
                crotch = z
            below = crotch is not None
            names.append(["torso" if m else ("leg" if below else "arm") for m in mid])
        return cls(levels, centres[::-1], hulls[::-1], names[::-1])


@dataclass(frozen=True)
class GarmentProfile:
    """A garment's closed loops per level of a ``BodySlices`` (list of ``Loop`` per level)."""

    garment_id: str
    loops: list[list[Loop]]

    @classmethod
    def build(cls, garment_id: str, vertices: np.ndarray, faces: np.ndarray, body: BodySlices,
              levels: range | None = None):  # fmt: skip
        """The profile of ``vertices (V, 3)``, ``faces (F, 3)``; with ``levels`` (indices into
        ``body.levels``) sliced at those levels only, the others left without loops."""
        out = []
        if levels is not None and len(levels):
            # Only the triangles that reach into the levels' span: the same slices, less to cut.
            z = vertices[faces, 2]
            lo, hi = body.levels[levels[0]], body.levels[levels[-1]]
            faces = faces[(z.max(axis=1) >= lo) & (z.min(axis=1) <= hi)]
        bottom, top = vertices[:, 2].min(), vertices[:, 2].max()
        for k, z in enumerate(body.levels):
            loops = []
            if (levels is None or k in levels) and bottom < z < top:
                for lp in slice_loops(vertices, faces, z):
                    if lp.closed and len(body.centres[k]):
                        inside = np.flatnonzero(lp.contains(body.centres[k]))
                        loops.append(Loop(lp.perimeter, frozenset(int(i) for i in inside)))
            out.append(loops)
        return cls(garment_id, out)


@dataclass(frozen=True)
class Refusal:
    inner: str
    outer: str
    reason: str


def _held_apart(inner: list[Loop], outer: list[Loop]) -> frozenset[int] | None:
    """Parts one inner loop joins that the outer loops touch but no outer loop holds together."""
    for a in inner:
        if len(a.parts) < 2:
            continue
        touching = [b for b in outer if b.parts & a.parts]
        if touching and not any(a.parts <= b.parts for b in touching):
            return a.parts
    return None


def junction_run(inner: GarmentProfile, outer: GarmentProfile, body: BodySlices):
    """The longest run of levels where ``outer`` holds apart parts ``inner`` wraps together: (its
    length in levels, the level at its top and the parts there), or None. A looser top's armhole that
    hangs below a fitted one's, a crotch below another's: the height the outer garment's junction
    would have to come down (or the inner one's go up)."""
    run, best, where = 0, 0, None
    for k in range(len(body.levels)):
        parts = _held_apart(inner.loops[k], outer.loops[k])
        run = run + 1 if parts is not None else 0
        if run > best:
            best, where = run, (k, parts)
    return None if where is None else (best, *where)


def topology_refusal(inner: GarmentProfile, outer: GarmentProfile, body: BodySlices) -> Refusal | None:
    """Rule 1: the longest run of levels where ``outer`` holds apart parts ``inner`` wraps together."""
    found = junction_run(inner, outer, body)
    if found is None:
        return None
    best, k, parts = found
    kinds = {body.names[k][i] for i in parts}
    if best * SETTINGS.slice_step <= min(SETTINGS.join_tolerance[kind] for kind in kinds):
        return None
    names = f"both {kinds.pop()}s" if len(kinds) == 1 else " and ".join(sorted(kinds))
    reason = (
        f"{inner.garment_id} wraps {names} in one piece over {100 * best * SETTINGS.slice_step:.0f} cm where "
        f"{outer.garment_id} goes around each separately: {outer.garment_id} cannot be worn over "
        f"{inner.garment_id} (the other order can)"
    )
    return Refusal(inner.garment_id, outer.garment_id, reason)


def girth_refusal(
    inner: GarmentProfile, outer: GarmentProfile, between: int, body: BodySlices
) -> Refusal | None:
    """Rule 2: the level where ``outer``'s stretched girth falls furthest short of ``inner`` pressed onto
    the body, ``between`` layers from the inner one to the outer one inclusive."""
    worst, at = 0.0, None
    for k in range(len(body.levels)):
        for a in inner.loops[k]:
            if not a.parts:
                continue
            for b in outer.loops[k]:
                if not a.parts <= b.parts:
                    continue
                need = hull_perimeter(np.concatenate([body.hulls[k][i] for i in a.parts]))
                need += 2 * np.pi * SETTINGS.margin * between
                short = need - b.perimeter * (1 + SETTINGS.stretch_limit)
                if short > worst:
                    worst, at = short, (k, b.perimeter, need)
    if at is None:
        return None
    k, have, need = at
    stretched = 100 * have * (1 + SETTINGS.stretch_limit)
    reason = (
        f"{outer.garment_id} is {100 * have:.0f} cm around at {100 * body.levels[k]:.0f} cm and stretches "
        f"to {stretched:.0f} cm, but {inner.garment_id} under it needs {100 * need:.0f} cm"
    )
    return Refusal(inner.garment_id, outer.garment_id, reason)


def refusals(profiles: dict[str, GarmentProfile], ids: list[str], body: BodySlices) -> list[Refusal]:
    """Every ordered pair (inner before outer in ``ids``) that rule 1 or rule 2 refuses."""
    out = []
    for i, inner in enumerate(ids):
        for j in range(i + 1, len(ids)):
            a, b = profiles[inner], profiles[ids[j]]
            found = topology_refusal(a, b, body) or girth_refusal(a, b, j - i, body)
            if found is not None:
                out.append(found)
    return out


class LayeringRule:
    """Rules 1 and 2 over a catalog: the body's slices and each garment's profile, made on first use
    and kept (a garment's profile is a fraction of a second; ``warm`` makes them all up front)."""

    def __init__(self, body_vertices: np.ndarray, body_faces: np.ndarray):
        self._body_mesh = (body_vertices, body_faces)
        self._body: BodySlices | None = None
        self._profiles: dict[str, GarmentProfile] = {}

    @property
    def body(self) -> BodySlices:
        if self._body is None:
            self._body = BodySlices.build(*self._body_mesh)
        return self._body

    def profile(self, garment) -> GarmentProfile:
        """``garment``: anything with ``id``, ``vertices`` and ``faces`` on the mean body (a Garment)."""
        if garment.id not in self._profiles:
            self._profiles[garment.id] = GarmentProfile.build(
                garment.id, garment.vertices, garment.faces, self.body
            )
        return self._profiles[garment.id]

    def holds_legs_apart(self, garment) -> bool:
        """Whether ``garment`` goes around each leg separately somewhere (pants, shorts; not a skirt):
        a top tucked into it can hang below its crotch (``collisions.squeeze.asks_segment_test``)."""
        body = self.body
        return any(
            len(loop.parts) == 1 and body.names[k][next(iter(loop.parts))] == "leg"
            for k, loops in enumerate(self.profile(garment).loops)
            for loop in loops
        )

    def warm(self, garments) -> None:
        for g in garments:
            self.profile(g)

    def refusals(self, garments: list) -> list[Refusal]:
        """Refusals of the stack ``garments`` (inner to outer)."""
        profiles = {g.id: self.profile(g) for g in garments}
        return refusals(profiles, [g.id for g in garments], self.body)


# --- slices -----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SliceLoop:
    """A connected piece of a slice: segments ``(S, 2, 2)`` in the plane, closed or not."""

    segments: np.ndarray
    closed: bool

    @property
    def perimeter(self) -> float:
        return float(np.linalg.norm(self.segments[:, 1] - self.segments[:, 0], axis=1).sum())

    @property
    def points(self) -> np.ndarray:
        return self.segments[:, 0]

    @property
    def centre(self) -> np.ndarray:
        """Length-weighted mean of the segment midpoints ``(2,)``."""
        w = np.linalg.norm(self.segments[:, 1] - self.segments[:, 0], axis=1) + 1e-12
        return (self.segments.mean(axis=1) * w[:, None]).sum(axis=0) / w.sum()

    def contains(self, p: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: points ``p (N, 2)`` inside the loop (parity of crossings of a ray along +x)."""
        a, b = self.segments[None, :, 0], self.segments[None, :, 1]
        y = p[:, None, 1]
        straddle = (a[..., 1] > y) != (b[..., 1] > y)
        t = (y - a[..., 1]) / np.where(straddle, b[..., 1] - a[..., 1], 1.0)
        x = a[..., 0] + t * (b[..., 0] - a[..., 0])
        return (np.sum(straddle & (x > p[:, None, 0]), axis=1) % 2) == 1


def slice_loops(vertices: np.ndarray, faces: np.ndarray, z: float) -> list[SliceLoop]:
    """The cross-section of a triangle mesh with the plane at height ``z``, as connected pieces: a
    triangle with vertices on both sides gives one segment between the two edges it crosses, and
    pieces are joined through the crossed edges they share (an edge crossed once: an open piece)."""
    above = vertices[:, 2] > z
    tri = faces[above[faces].sum(axis=1) % 3 != 0]  # (T, 3): triangles the plane crosses
    if not len(tri):
        return []
    # Each crossed triangle has exactly two crossed edges: (a, b) with a above and b below or v.v.
    edges = np.stack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]], axis=1)  # (T, 3, 2)
    crossed = above[edges[..., 0]] != above[edges[..., 1]]
    pick = edges[crossed].reshape(len(tri), 2, 2)
    keys = np.sort(pick, axis=2)
    pa, pb = vertices[keys[..., 0]], vertices[keys[..., 1]]
    t = (z - pa[..., 2]) / (pb[..., 2] - pa[..., 2])
    points = pa[..., :2] + t[..., None] * (pb[..., :2] - pa[..., :2])  # (T, 2, 2)
    # Join segments sharing a crossed edge: connected components of the graph whose nodes are the
    # crossed edges and whose links are the segments.
    _, edge_id = np.unique(keys[..., 0] * len(vertices) + keys[..., 1], return_inverse=True)
    edge_id = edge_id.reshape(len(tri), 2)
    n = int(edge_id.max()) + 1
    graph = coo_matrix((np.ones(len(tri)), (edge_id[:, 0], edge_id[:, 1])), shape=(n, n))
    _, roots = connected_components(graph, directed=False)
    uses = np.bincount(edge_id.ravel(), minlength=n)
    component = roots[edge_id[:, 0]]
    open_edge = uses != 2
    out = []
    for r in np.unique(component):
        members = component == r
        out.append(SliceLoop(points[members], not bool(open_edge[roots == r].any())))
    return out


def _cross2(u: np.ndarray, v: np.ndarray) -> float:
    return float(u[0] * v[1] - u[1] * v[0])


def hull_perimeter(points: np.ndarray) -> float:
    """Perimeter (m) of the convex hull of ``points (N, 2)`` (monotone chain)."""
    p = np.unique(np.round(points, 9), axis=0)
    if len(p) < 3:
        return float(2 * np.linalg.norm(p[-1] - p[0])) if len(p) == 2 else 0.0

    def half(pts):
        h = []
        for q in pts:
            while len(h) >= 2 and _cross2(h[-1] - h[-2], q - h[-2]) <= 0:
                h.pop()
            h.append(q)
        return h

    hull = np.array(half(p)[:-1] + half(p[::-1])[:-1])
    return float(np.linalg.norm(np.roll(hull, -1, axis=0) - hull, axis=1).sum())
