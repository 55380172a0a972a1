"""Horizontal sections of a closed triangle mesh and the girths a tape measure reads off them.

A tape laid horizontally around a body at height z touches the body's section at z where the section
bulges out and bridges its hollows in straight lines: its length is the perimeter of the section's
convex hull. ``tape_girth`` measures that around one chosen loop of the section (the torso's, not
the arms'); ``tape_girths`` does it at many heights and checks the mesh once.

Meshes are ``vertices (V, 3) float`` and ``faces (F, 3) int``, closed (every edge shared by two
faces) and consistently oriented, counter-clockwise seen from outside (``service.geometry.mesh``).
A vertex exactly at z counts as below the plane, so a section through vertices is well defined.
Section loops come back counter-clockwise seen from +z for an outward-oriented surface (a hole in
the section, e.g. a tube's inner wall, runs clockwise).

Fast paths and their references (tests/geometry/test_girth.py): ``convex_hull`` (Andrew's monotone
chain, compiled) against ``scipy.spatial.ConvexHull``; ``tape_girth`` against Ramanujan's ellipse
perimeter on an elliptic cylinder and against the hull of the raw triangle-plane crossings.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from service.geometry.mesh import check_mesh

# ---------------------------------------------------------------- sections


def _check_points(points: np.ndarray) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points must be (K, 2), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("points must be finite")
    return p


def _check_level(z: float) -> float:
    z = float(z)
    if not np.isfinite(z):
        raise ValueError(f"z must be finite, got {z}")
    return z


# Up to this many heights a slicer masks every face per height rather than sorting them once (measured:
# sorting Anny's faces costs about as much as 30 masks).
FEW_LEVELS = 30


class _Slicer:
    """A checked mesh ready to be sliced at many heights: faces sorted by their lowest corner, so the
    faces a plane can cross are one contiguous run found by binary search. ``sort=False`` skips the
    sort (~3 ms for Anny's 26.7k faces) for a few heights: each then masks every face (~0.1 ms)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, sort: bool = True):
        check_mesh(vertices, faces)
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
        fz = self.vertices[:, 2][faces]  # (F, 3)
        lowest = fz.min(axis=1)
        self.sorted = sort
        if sort:
            order = np.argsort(lowest, kind="stable")
            faces, fz, lowest = faces[order], fz[order], lowest[order]
        self.faces, self.fz, self.lowest = faces, fz, lowest
        self.highest = self.fz.max(axis=1)
        self.span = float((self.highest - self.lowest).max()) if len(faces) else 0.0

    def crossing_edges(self, z: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The plane z's crossings: node points ``(N, 2)`` (one per crossed edge), ``succ (N,)``, the
        node after each along the section (face orientation), and each node's edge ``a, b (N,)`` int
        and parameter ``t (N,)`` (the point is ``a + t (b - a)``). Raises ValueError where the section
        is open (a crossed edge with one face: the mesh has a boundary there) or not a set of loops."""
        # A crossed face has lowest <= z < highest <= lowest + span.
        if self.sorted:
            run = slice(*np.searchsorted(self.lowest, [z - self.span, z], side="right"))
            hit = self.highest[run] > z
        else:
            run, hit = slice(None), (self.lowest <= z) & (self.highest > z)
        tri = self.faces[run][hit]
        n_vertices = len(self.vertices)
        if not len(tri):
            empty = np.empty(0, dtype=np.int64)
            return np.empty((0, 2)), empty, empty, empty, np.empty(0)
        above = self.fz[run][hit] > z  # (T, 3)
        # Edge k runs from corner k to corner k + 1; exactly one edge of a crossed triangle goes down
        # (above -> below) and one goes up. The section runs from the down edge to the up edge:
        # counter-clockwise seen from +z around an outward-oriented surface.
        nxt = above[:, [1, 2, 0]]
        rows = np.arange(len(tri))
        down = np.argmax(above & ~nxt, axis=1)
        up = np.argmax(~above & nxt, axis=1)
        ends = np.stack(
            [tri[rows, down], tri[rows, (down + 1) % 3], tri[rows, up], tri[rows, (up + 1) % 3]], 1
        )
        lo = np.minimum(ends[:, 0::2], ends[:, 1::2])  # (T, 2): [down edge, up edge], smaller index
        hi = np.maximum(ends[:, 0::2], ends[:, 1::2])
        keys, node = np.unique(lo * n_vertices + hi, return_inverse=True)
        node = node.reshape(len(tri), 2)
        if np.any(np.bincount(node.ravel(), minlength=len(keys)) != 2):
            raise ValueError(f"the section at z={z:g} is open: the mesh is not closed there")
        ia, ib = keys // n_vertices, keys % n_vertices
        a, b = self.vertices[ia], self.vertices[ib]
        t = (z - a[:, 2]) / (b[:, 2] - a[:, 2])
        points = a[:, :2] + t[:, None] * (b[:, :2] - a[:, :2])
        succ = np.full(len(keys), -1, dtype=np.int64)
        succ[node[:, 0]] = node[:, 1]
        if np.any(succ < 0):
            raise ValueError(
                f"the section at z={z:g} is not a set of loops: the faces' orientations disagree"
            )
        return points, succ, ia, ib, t

    def crossings(self, z: float) -> tuple[np.ndarray, np.ndarray]:
        """Node points ``(N, 2)`` and ``succ (N,)`` of ``crossing_edges``."""
        points, succ, _, _, _ = self.crossing_edges(z)
        return points, succ

    def loops(self, z: float) -> list[np.ndarray]:
        return _loops(*self.crossings(z))


@njit(cache=True, nogil=True)
def _order_cycles(succ):
    """Nodes ``(N,)`` in loop order and loop start offsets ``(L + 1,)`` of the permutation succ."""
    n = len(succ)
    seen = np.zeros(n, dtype=np.bool_)
    order = np.empty(n, dtype=np.int64)
    starts = np.empty(n + 1, dtype=np.int64)
    k = 0
    loops = 0
    for s in range(n):
        if seen[s]:
            continue
        starts[loops] = k
        loops += 1
        v = s
        while not seen[v]:
            seen[v] = True
            order[k] = v
            k += 1
            v = succ[v]
    starts[loops] = k
    return order, starts[: loops + 1]


def _loops(points: np.ndarray, succ: np.ndarray) -> list[np.ndarray]:
    if not len(succ):
        return []
    order, starts = _order_cycles(succ)
    return [points[order[s:e]] for s, e in zip(starts[:-1], starts[1:], strict=True)]


def section_loops(vertices: np.ndarray, faces: np.ndarray, z: float) -> list[np.ndarray]:
    """The section of a closed mesh with the plane at height z, as closed polylines ``(K, 2)`` (x, y;
    the last point joins the first, not repeated), counter-clockwise around the solid's material.

    vertices (V, 3) float, faces (F, 3) int (closed, consistently oriented); z a finite height. An
    empty list where the plane misses the mesh. Raises ValueError on bad input or where the section
    is open (the mesh has a boundary crossing z)."""
    return _Slicer(vertices, faces).loops(_check_level(z))


def signed_area(loop: np.ndarray) -> float:
    """Shoelace area of a closed polyline ``(K, 2)``: positive counter-clockwise."""
    p = _check_points(loop)
    q = np.roll(p, -1, axis=0)
    return float(0.5 * np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))


def encloses(loop: np.ndarray, point: np.ndarray) -> bool:
    """Whether the closed polyline ``loop (K, 2)`` winds around ``point (2,)`` (even-odd rule)."""
    p = _check_points(loop)
    x, y = np.asarray(point, dtype=np.float64).reshape(2)
    if not len(p) or not (p[:, 0].min() <= x <= p[:, 0].max() and p[:, 1].min() <= y <= p[:, 1].max()):
        return False
    q = np.roll(p, -1, axis=0)
    straddles = (p[:, 1] > y) != (q[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = p[:, 0] + (y - p[:, 1]) * (q[:, 0] - p[:, 0]) / (q[:, 1] - p[:, 1])
    return bool(np.count_nonzero(straddles & (x < x_cross)) % 2)


# ---------------------------------------------------------------- convex hull and tape


@njit(cache=True, nogil=True, inline="always")
def _turn(hull, k, q):
    """Cross product of (hull[k-1] - hull[k-2]) and (q - hull[k-2]): > 0 for a left turn."""
    ax, ay = hull[k - 1, 0] - hull[k - 2, 0], hull[k - 1, 1] - hull[k - 2, 1]
    return ax * (q[1] - hull[k - 2, 1]) - ay * (q[0] - hull[k - 2, 0])


@njit(cache=True, nogil=True)
def _monotone_chain(p):
    """Hull of points ``p (N, 2)`` sorted by (x, y), counter-clockwise, collinear points dropped."""
    n = len(p)
    hull = np.empty((2 * n, 2))
    k = 0
    for i in range(n):  # lower hull
        while k >= 2 and _turn(hull, k, p[i]) <= 0.0:
            k -= 1
        hull[k] = p[i]
        k += 1
    lower = k + 1
    for i in range(n - 2, -1, -1):  # upper hull
        while k >= lower and _turn(hull, k, p[i]) <= 0.0:
            k -= 1
        hull[k] = p[i]
        k += 1
    return hull[: max(k - 1, 1)]


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Vertices ``(H, 2)`` of the convex hull of ``points (K, 2)``, K >= 1, counter-clockwise from
    the lowest-x (then lowest-y) point, without collinear or repeated points. Fewer than three
    distinct or only collinear points give their two ends (two equal points where all are one)."""
    p = _check_points(points)
    if not len(p):
        raise ValueError("convex_hull needs at least one point")
    p = np.ascontiguousarray(p[np.lexsort((p[:, 1], p[:, 0]))])
    return _monotone_chain(p)


def polyline_length(loop: np.ndarray) -> float:
    """Length of the closed polyline ``loop (K, 2)`` (the last point joins the first)."""
    p = _check_points(loop)
    return float(np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1).sum()) if len(p) > 1 else 0.0


def convex_perimeter(points: np.ndarray) -> float:
    """Tape girth of ``points (K, 2)``: the perimeter of their convex hull (twice the length of a
    flat piece, 0 for one point)."""
    return polyline_length(convex_hull(points))


def _outermost_around(loops: list[np.ndarray], point: np.ndarray) -> np.ndarray | None:
    """The largest of the loops that go around ``point (2,)``, None if none does."""
    around = [loop for loop in loops if encloses(loop, point)]
    return max(around, key=lambda loop: abs(signed_area(loop))) if around else None


def tape_loop(vertices: np.ndarray, faces: np.ndarray, z: float, select: np.ndarray) -> np.ndarray:
    """Where a horizontal tape lies at height z around the section loop that goes around the point
    ``select (2,)`` (x, y): the convex hull ``(H, 2)`` of the outermost such loop (other loops, e.g.
    the arms' beside the torso, are left out). Raises ValueError where no loop goes around it."""
    z = _check_level(z)
    point = _check_points(np.reshape(select, (1, 2)))[0]
    loop = _outermost_around(_Slicer(vertices, faces).loops(z), point)
    if loop is None:
        raise ValueError(f"no loop of the section at z={z:g} goes around {tuple(point.tolist())}")
    return convex_hull(loop)


def tape_girth(vertices: np.ndarray, faces: np.ndarray, z: float, select: np.ndarray) -> float:
    """Length (mesh units) of ``tape_loop``: the girth a tape reads at height z around ``select``."""
    return polyline_length(tape_loop(vertices, faces, z, select))


def _checked_levels(zs: np.ndarray, select: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    zs = np.asarray(zs, dtype=np.float64).reshape(-1)
    if not np.all(np.isfinite(zs)):
        raise ValueError("zs must be finite")
    sel = np.asarray(select, dtype=np.float64)
    sel = np.broadcast_to(sel, (len(zs), 2)) if sel.shape == (2,) else sel
    _check_points(sel)
    if len(sel) != len(zs):
        raise ValueError(f"select must be (2,) or ({len(zs)}, 2), got {np.shape(select)}")
    return zs, np.ascontiguousarray(sel)


def tape_girths(
    vertices: np.ndarray, faces: np.ndarray, zs: np.ndarray, select: np.ndarray
) -> tuple[np.ndarray, list[np.ndarray]]:
    """``tape_girth`` at each height of ``zs (L,)`` around ``select``, one point ``(2,)`` for all
    heights or one per height ``(L, 2)``: girths ``(L,)`` and the tapes' hulls (a list of L ``(H, 2)``).
    A height where no loop goes around its point gives NaN and an empty ``(0, 2)`` hull instead of
    raising. Checks and sorts the mesh once; past ``FEW_LEVELS`` heights the sections are compiled
    (``girth_kernel``): ``tape_girths_reference``'s hulls and girths, bit for bit."""
    from service.geometry.girth_kernel import NOT_LOOPS, OPEN, tape_hulls

    zs, sel = _checked_levels(zs, select)
    if len(zs) <= FEW_LEVELS:
        return tape_girths_reference(vertices, faces, zs, sel)
    s = _Slicer(vertices, faces)
    # Writable and C-ordered, every one: numba compiles another version for each array type it meets
    # (a frozen body's read-only vertices would be one), and only one is compiled ahead of use.
    mesh = (np.require(a, requirements=["C", "W"]) for a in (s.vertices, s.faces, s.fz, s.lowest, s.highest))
    levels = (np.require(a, requirements=["C", "W"]) for a in (zs, sel))
    corners, starts, error = tape_hulls(*mesh, s.span, *levels)
    if error.any():
        first = np.flatnonzero(error)[0]
        why = {OPEN: "is open: the mesh is not closed there",
               NOT_LOOPS: "is not a set of loops: the faces' orientations disagree"}[error[first]]
        raise ValueError(f"the section at z={zs[first]:g} {why}")
    hulls = [corners[a:b] for a, b in zip(starts[:-1], starts[1:], strict=True)]
    # Each corner's edge to the next of its hull (the last to the first), all hulls at once: the same
    # rows ``polyline_length`` rolls, summed per hull as it sums them (1 ms less than hull by hull).
    nxt = np.arange(1, len(corners) + 1)
    ends = starts[1:][starts[1:] > starts[:-1]]
    nxt[ends - 1] = starts[:-1][starts[1:] > starts[:-1]]
    edges = np.linalg.norm(corners[nxt % max(len(corners), 1)] - corners, axis=1)
    girths = np.array([edges[a:b].sum() if b - a > 1 else (0.0 if b > a else np.nan)
                       for a, b in zip(starts[:-1], starts[1:], strict=True)])  # fmt: skip
    return girths, hulls


def tape_girths_reference(
    vertices: np.ndarray, faces: np.ndarray, zs: np.ndarray, select: np.ndarray
) -> tuple[np.ndarray, list[np.ndarray]]:
    """``tape_girths`` height by height in numpy (``_Slicer.loops``, ``_outermost_around``)."""
    slicer = _Slicer(vertices, faces, sort=np.size(zs) > FEW_LEVELS)
    zs, sel = _checked_levels(zs, select)
    girths, hulls = np.full(len(zs), np.nan), []
    for i, (z, point) in enumerate(zip(zs, sel, strict=True)):
        loop = _outermost_around(slicer.loops(z), point)
        hulls.append(np.empty((0, 2)) if loop is None else convex_hull(loop))
        if loop is not None:
            girths[i] = polyline_length(hulls[-1])
    return girths, hulls


@dataclass(frozen=True, eq=False)
class TapeEdges:
    """Where a tape's corners come from: corner i is ``vertices[a_i] + t_i (vertices[b_i] - vertices[a_i])``
    (x, y) at height z, so the girth's derivative w.r.t. the vertices follows (``body_fit``).

    points: (H, 2) the hull's corners, counter-clockwise; a, b: (H,) int mesh edges; t: (H,) float.
    """

    points: np.ndarray
    a: np.ndarray
    b: np.ndarray
    t: np.ndarray

    @property
    def girth(self) -> float:
        return polyline_length(self.points)


def tape_edges(
    vertices: np.ndarray, faces: np.ndarray, zs: np.ndarray, select: np.ndarray
) -> list[TapeEdges]:
    """``tape_loop`` at each height ``zs (L,)`` around ``select (2,)``, with each hull corner's mesh
    edge (``TapeEdges``). Raises ValueError where no loop goes around the point."""
    zs = np.asarray(zs, dtype=np.float64).reshape(-1)
    slicer = _Slicer(vertices, faces, sort=len(zs) > FEW_LEVELS)
    point = _check_points(np.reshape(select, (1, 2)))[0]
    out = []
    for z in zs:
        points, succ, a, b, t = slicer.crossing_edges(_check_level(z))
        best = None
        if len(succ):
            order, starts = _order_cycles(succ)
            loops = [order[s:e] for s, e in zip(starts[:-1], starts[1:], strict=True)]
            around = [ix for ix in loops if encloses(points[ix], point)]
            best = max(around, key=lambda ix: abs(signed_area(points[ix]))) if around else None
        if best is None:
            raise ValueError(f"no loop of the section at z={z:g} goes around {tuple(point.tolist())}")
        hull = convex_hull(points[best])
        # The hull's corners are copies of loop points: find which (exact equality).
        key = {(x, y): i for i, (x, y) in zip(best.tolist(), points[best].tolist(), strict=True)}
        idx = np.array([key[(x, y)] for x, y in hull.tolist()], dtype=np.int64)
        out.append(TapeEdges(hull, a[idx], b[idx], t[idx]))
    return out
