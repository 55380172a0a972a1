"""Exact collision repair of one garment in world space, against its final inner layers.

The field fit (``service.pipeline.fit``) untangles the layers as the learned fields see them; those are
~1-2 mm off the meshes, and a fitted mesh can still cross an inner one by that much. This pass moves the
layer outwards, round by round, towards the quality measures of docs/design.md section 7 (no triangle
crossing an inner layer, no vertex inside one), layer by layer from the body outwards (inner layers are
final when an outer one is repaired). It does not promise to get there: it keeps the round with the
fewest faults (crossing pairs, then vertices inside), stops after ``repair_rounds`` rounds or
``repair_patience`` rounds without a new fewest, and returns that round with the faults it left
(``RepairResult``). Each round:

1. Vertices of the layer closer than ``margin`` to an inner layer on its outer side, or on its inner
   side within ``PENETRATION_BAND`` where the inner garment covers (its covariant field h < 0, as in
   ``service.pipeline.quality.penetration``), move along the inner layer's normal to ``margin`` outside it.
   The body is a closed mesh: every vertex inside it or closer than ``margin`` moves out.
2. The displacement spreads over ``repair_ring`` rings of neighbours (Laplacian diffusion with the moved
   vertices held), so a push lifts a patch instead of a spike.
3. Exact edge-triangle tests find the triangle pairs still crossing (an inner bump poking between
   outer vertices); their outer vertices get a larger margin (``growth``, up to ``max_margin``)
   and, in the next round, their corners are lifted along the inner surface's normal clear of the
   inner triangles they cross (``lifts``), and the loop repeats.

Everything is local to the vertices that the fields place within ``CollisionSettings.reach`` of an
inner layer (the caller's ``Inner.near``): most vertices are far from every inner layer and are never
queried.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from service.geometry.clear_of import clear_of
from service.geometry.closest import ClosestPoint
from service.geometry.diffusion import diffuse
from service.geometry.fold_side import FoldSides
from service.geometry.intersections import TriangleGrid
from service.geometry.kept_queries import KeptQueries
from service.geometry.mesh import vertex_normals
from service.geometry.rings import dilate, vertex_neighbours
from service.pipeline.collisions.settings import SETTINGS, CollisionSettings
from service.pipeline.quality import PENETRATION_BAND
from service.process.threads import pool


@dataclass
class Inner:
    """An inner layer as one outer layer sees it."""

    mesh: ClosestPoint  # its final world-space mesh
    closed: bool  # the body: inside is inside, at any depth
    near: np.ndarray  # (V,) bool: outer vertices that may come within reach of it (others never move)
    covered: np.ndarray  # (V,) bool: outer vertices it covers (its h < 0 there); all for the body
    query: np.ndarray | None = None
    """(V,) bool: the near vertices that may be inside it or within the margin, whose closest points
    the pushes need (None: all near ones). Vertices of triangles found crossing it are asked too,
    whatever this says: the exact crossing tests cover every near triangle."""
    kept: KeptQueries | None = None
    """Closest points on ``mesh`` already asked for (of these V vertices), or None: none yet."""
    reversed_faces: np.ndarray | None = None
    """(F,) bool: faces of ``mesh`` that may face the body (``service.geometry.anchors.BodyAnchors.
    reversed_faces``: a fold's middle sheet, and at an armpit faces that lie the usual way); None: none."""
    sides: FoldSides | None = None
    """Its side test (``service.geometry.fold_side``) for the vertices closest to ``reversed_faces``, the
    one ``quality.penetration`` reads; None: those faces are turned over."""


@dataclass
class RepairResult:
    vertices: np.ndarray  # (V, 3)
    moved: np.ndarray  # (V,) bool: vertices displaced by the repair
    rounds: int
    crossing_pairs: int  # triangle pairs still crossing an inner layer at the end (0 = success)
    inside: int  # vertices still inside an inner layer at the end (0 = success)
    log: list[dict] = field(default_factory=list)
    faults: list[np.ndarray] = field(default_factory=list)
    """Per inner layer, ``(K,)`` indices of its own vertices where the faults left are: the corners of its
    triangles still crossing this layer, and the closest-face corners of this layer's vertices inside it
    (``service.pipeline.collisions.passes`` presses the inner garment deeper there in its next pass)."""


def _pushes(x: np.ndarray, inner: Inner, margin: np.ndarray, forced: np.ndarray, queries=None,
            short_of_margin: float = SETTINGS.short_of_margin):  # fmt: skip
    """The vertices of ``x (V, 3)`` that violate ``margin (V,)`` against ``inner``, where they go, and
    which of them are inside it: (indices (K,), targets (K, 3), inside (J,) indices). ``forced (V,)``
    marks vertices of crossing triangles: inside the inner layer they move out even where its covariant
    field says it does not cover them (a T-shirt's hem poking through the pants it is tucked into).
    ``queries`` (``KeptQueries`` of ``inner.mesh``) keeps the closest points of the vertices that did
    not move."""
    ask = inner.near if inner.query is None else inner.near & (inner.query | forced)
    near = np.flatnonzero(ask)
    if not len(near):
        return near, np.zeros((0, 3)), near
    signed, point, normal, rim = (queries or KeptQueries(inner.mesh, len(x))).at(x, near)
    inside = signed < 0
    # A vertex pushed to the margin last round lands a rounding error short of it: 10 % slack stops
    # the loop from pushing it again and again by nothing.
    short = signed < short_of_margin * margin[near]
    covered = inner.covered[near] | forced[near]
    # A vertex whose closest point is on the inner garment's rim is past its opening, not on either
    # side of it (a long sleeve leaving a T-shirt's sleeve; the learned h is blurred there): pushed
    # along the rim's face it went through the underarm. Only a crossing forces it.
    past = rim & ~forced[near]
    bad = short & (inner.closed | (~past & (~inside | ((signed > -PENETRATION_BAND) & covered))))
    idx = near[bad]
    # Out along the face normal from the closest point, to the margin.
    return idx, point[bad] + margin[idx, None] * normal[bad], near[bad & inside]


def _faces_around(mesh: ClosestPoint, points: np.ndarray, pad: float) -> np.ndarray:
    """Indices of ``mesh``'s faces with a vertex inside the bounding box of ``points (P, 3)`` (the
    corners of the triangles tested against it) grown by ``pad``."""
    if not len(points):
        return np.zeros(0, dtype=np.int64)
    lo, hi = points.min(axis=0) - pad, points.max(axis=0) + pad
    v = mesh.vertices
    inside = (v[:, 0] >= lo[0]) & (v[:, 0] <= hi[0]) & (v[:, 1] >= lo[1]) & (v[:, 1] <= hi[1])
    inside &= (v[:, 2] >= lo[2]) & (v[:, 2] <= hi[2])
    f = mesh.faces
    return np.flatnonzero(inside[f[:, 0]] | inside[f[:, 1]] | inside[f[:, 2]])


def repair_layer(
    vertices: np.ndarray, faces: np.ndarray, inner: list[Inner], settings: CollisionSettings = SETTINGS
) -> RepairResult:
    """Repair one layer ``vertices (V, 3)``, ``faces (F, 3)`` against its final ``inner`` layers."""
    x = np.asarray(vertices, dtype=np.float64).copy()
    faces = np.asarray(faces)
    adjacency = vertex_neighbours(faces, len(x))
    margin = np.full(len(x), settings.margin)
    forced = np.zeros(len(x), dtype=bool)
    kick = np.zeros(len(x))  # m: outward push of vertices of still-crossing triangles
    # Corners of crossing triangles lifted clear of the inner triangles they cross (``lifts``).
    no_lift = np.zeros(0, dtype=np.int64)
    lift_at, lift = no_lift, np.zeros((0, 3))
    # Only triangles with a vertex near an inner layer can cross it, and only the inner triangles
    # around those (the rest of a body never changes between rounds).
    tested = [np.flatnonzero(layer.near[faces].any(axis=1)) for layer in inner]

    def grid(n: int, points: np.ndarray) -> tuple[TriangleGrid, np.ndarray]:
        around = _faces_around(inner[n].mesh, points, PENETRATION_BAND)
        return TriangleGrid.build(inner[n].mesh.vertices, inner[n].mesh.faces[around]), around

    def corners(n: int) -> np.ndarray:
        """The tested triangles' corners as they are now (a copy: the rounds move ``x``)."""
        used = np.zeros(len(x), dtype=bool)
        used[faces[tested[n]].ravel()] = True
        return x[used]

    # One grid per inner layer, built side by side on their own threads (the cell lists are compiled and
    # release the GIL) while the first round's pushes run: the crossing tests are the first to need them.
    pending = [pool("grids", 2).submit(grid, n, corners(n)) for n in range(len(inner))]
    built = None
    queries = [KeptQueries(layer.mesh, len(x), layer.reversed_faces, layer.sides) if layer.kept is None
               else layer.kept for layer in inner]  # fmt: skip
    # Crossing pairs (tested triangle, inner triangle) of each layer, and the vertices they were
    # found at: a triangle none of whose vertices moved keeps its pairs (the inner layers are fixed).
    hits = [np.zeros((0, 2), dtype=np.int64) for _ in inner]
    tested_at = np.full_like(x, np.nan)
    log = []
    crossing, rounds = -1, 0  # -1: not tested yet
    best = _Round(np.inf, x.copy(), -1, -1, 0, [])
    while True:
        held = np.zeros(len(x), dtype=bool)
        u = np.zeros_like(x)
        inside, inside_at = 0, []
        for layer, q in zip(inner, queries, strict=True):
            idx, target, within = _pushes(x + u, layer, margin, forced, q, settings.short_of_margin)
            u[idx] = target - x[idx]
            held[idx] = True
            inside += len(within)
            inside_at.append(within)
        if crossing >= 0 and crossing + inside < best.faults:
            places = [(h[:, 1].copy(), w) for h, w in zip(hits, inside_at, strict=True)]
            best = _Round(crossing + inside, x.copy(), crossing, inside, rounds, places)
        # Done when the current meshes cross nothing and no vertex is inside an inner layer: the margin
        # is a cushion, not a measure (a vertex squeezed between two inner layers closer than the margin
        # would otherwise be pushed back and forth until the round cap).
        if (crossing == 0 and inside == 0) or rounds == settings.repair_rounds:
            break
        if rounds - best.round >= settings.repair_patience:  # the faults no longer fall: an oscillation
            break
        rounds += 1
        # A crossing that survives its vertices' margins is an inner feature between them (fingers in a
        # sleeve, a T-shirt's hem inside the pants): the corners are lifted clear of the inner triangles
        # they cross (``lifts``), and those it leaves bulge out along the layer's own normal.
        bulge = kick > 0
        if len(lift_at):
            # A corner that a push also moves takes the larger of the two. Lifted in place of every
            # push, the pants over a tucked T-shirt's hem tore into spikes (tshirt < jacket < pants <
            # long sleeve: 0 -> 9 pairs); pushed in place of every lift, a tank top's hem stayed
            # through a T-shirt's (skirt < jacket < tshirt < tank top: 0 -> 67).
            free = ~held[lift_at] | (np.linalg.norm(lift, axis=1) > np.linalg.norm(u[lift_at], axis=1))
            u[lift_at[free]] = lift[free]
            held[lift_at[free]] = True
            bulge[lift_at[free]] = False
        if bulge.any():
            u[bulge] += kick[bulge, None] * vertex_normals(x, faces)[bulge]
            held |= bulge
        if held.any():
            region = dilate(held, adjacency, settings.repair_ring)
            u = diffuse(u, held, region, adjacency, settings.repair_smoothing)
            x += u
        crossing, culprits = 0, []
        if built is None:
            built = [p.result() for p in pending]
            grids = [g for g, _ in built]
        moved = np.any(x != tested_at, axis=1)
        tested_at = x.copy()
        for n, (t, grid) in enumerate(zip(tested, grids, strict=True)):
            changed = np.flatnonzero(moved[faces[t]].any(axis=1))
            # A moved triangle's old pairs go, whether it is tested again or proved clear now.
            again = changed[~clear_of(x, faces[t[changed]], queries[n])]
            pairs = grid.crossing(x, faces[t[again]])
            pairs[:, 0] = again[pairs[:, 0]]
            hits[n] = np.concatenate([hits[n][~np.isin(hits[n][:, 0], changed)], pairs])
            crossing += len(hits[n])
            culprits.append(faces[t][hits[n][:, 0]].ravel())
        log.append({"pushed": int(held.sum()), "inside": inside, "crossing_pairs": crossing})
        kick[:] = 0.0
        lift_at = no_lift
        if crossing:
            worse = np.unique(np.concatenate(culprits))
            forced[worse] = True
            margin[worse] = np.minimum(settings.growth * margin[worse], settings.max_margin)
            kick[worse] = settings.margin
            if settings.lift > 0:
                inner_faces = [(layer, around) for layer, (_, around) in zip(inner, built, strict=True)]
                lift_at, lift = lifts(x, [faces[t] for t in tested], hits, inner_faces, settings)
    if built is None:  # no round ran
        built = [p.result() for p in pending]
    places = [(h[:, 1].copy(), w) for h, w in zip(hits, inside_at, strict=True)]
    if crossing + inside > best.faults:  # stopped while oscillating: return the round with the fewest faults
        x, crossing, inside, places = best.vertices, best.crossing, best.inside, best.places
    moved = np.any(x != np.asarray(vertices, dtype=np.float64), axis=1)
    faults = [_fault_corners(layer.mesh, x, around, *where)
              for layer, (_, around), where in zip(inner, built, places, strict=True)]  # fmt: skip
    return RepairResult(x, moved, rounds, crossing, inside, log, faults)


@dataclass(frozen=True)
class _Round:
    """The round of ``repair_layer`` with the fewest faults so far: their count (crossing pairs plus
    vertices inside), the layer's vertices ``(V, 3)`` then, each count, the round, and per inner layer
    where the faults were (its crossed faces, the inside vertices)."""

    faults: float
    vertices: np.ndarray
    crossing: int
    inside: int
    round: int
    places: list[tuple[np.ndarray, np.ndarray]]


def lifts(
    x: np.ndarray,
    tested_faces: list[np.ndarray],
    hits: list[np.ndarray],
    inner: list[tuple[Inner, np.ndarray]],
    settings: CollisionSettings,
) -> tuple[np.ndarray, np.ndarray]:
    """Where the corners of crossing triangles go to clear the inner triangles they cross.

    Per inner layer n: ``tested_faces[n] (T, 3)`` corners (of ``x (V, 3)``) of the tested triangles,
    ``hits[n] (P, 2)`` crossing pairs (tested triangle, index into ``around``) and ``inner[n]`` = (the
    ``Inner``, ``around (A,)`` its faces the pairs index). A corner's direction is the mean outward
    normal of the inner faces its triangles cross (the inner surface there: both walls of a fold poking
    through give its top); along it, the corner moves until it is ``margin`` above the highest corner of
    each inner triangle its triangles cross, by at most ``settings.lift``.

    Why: an inner fold poking up between the corners of a stretched outer triangle (a tank top's 4 cm
    triangles over a jacket's armpit, corners 7-15 mm out) is past every margin; a kick of ``margin`` a
    round along the layer's own normal, spread over the rings around it, left jacket < tank top < long
    sleeve with 13 such pairs after 15 rounds, and 0 lifted. Directions tried before this one, on that
    stack and skirt < jacket < T-shirt < tank top (one-off runs): each triangle rigidly along its own
    normal (which clears a pair for certain) moved cloth sideways where the outer triangle stands steep
    to the inner layer, 529 and 596 pairs; the inner layer's normal at the corner's closest point, 0 and
    8, and 82 of 85 clean on ``benchmarks.orders --stacks 100`` seed 7 (84 before); each pair's own inner
    face normal, 0 and 0, but it moves corners sideways off a knife-edge ridge's walls (the test).

    Returns (corner indices (K,), displacements (K, 3))."""
    at, moves, heights = [], [], []
    for n, (layer, around) in enumerate(inner):
        if not len(hits[n]):
            continue
        outer_corners = tested_faces[n][hits[n][:, 0]].ravel()  # (3P,)
        face = np.repeat(around[hits[n][:, 1]], 3)  # (3P,) the inner face each corner's pair crosses
        # Each corner's direction: the mean of the outward normals of the inner faces its pairs cross.
        face_normal = layer.mesh.fn[face]
        # Flagged faces are turned over, not read by ``sides``: a lift wants "away from the body", and
        # oriented by the crossing parity (a probe 0.1 mm off each face) seed 7's skirt < jacket <
        # T-shirt < long sleeve went from 24 to 326 pairs.
        if layer.reversed_faces is not None:
            face_normal = np.where(layer.reversed_faces[face][:, None], -face_normal, face_normal)
        corner, back = np.unique(outer_corners, return_inverse=True)
        normal = np.zeros((len(corner), 3))
        np.add.at(normal, back, face_normal)
        length = np.linalg.norm(normal, axis=1)
        normal = (normal / np.where(length > 0, length, 1.0)[:, None])[back]
        crossed = layer.mesh.vertices[layer.mesh.faces[face]]  # (3P, 3, 3)
        above = np.einsum("pkd,pd->pk", crossed - x[outer_corners][:, None], normal).max(axis=1)
        h = np.minimum(above + settings.margin, settings.lift)
        up = h > 0
        at.append(outer_corners[up])
        heights.append(h[up])
        moves.append(normal[up] * h[up, None])
    at = np.concatenate(at) if at else np.zeros(0, dtype=np.int64)
    if not len(at):
        return at, np.zeros((0, 3))
    heights, moves = np.concatenate(heights), np.concatenate(moves)
    # Each corner's largest: sorted by height, the last of each corner's run.
    order = np.lexsort((heights, at))
    at, moves = at[order], moves[order]
    last = np.flatnonzero(np.append(at[1:] != at[:-1], True))
    return at[last], moves[last]


def _fault_corners(mesh: ClosestPoint, x: np.ndarray, around: np.ndarray, crossed: np.ndarray,
                   inside: np.ndarray) -> np.ndarray:  # fmt: skip
    """``(K,)`` vertices of the inner ``mesh`` at the faults: the corners of its triangles ``around[crossed]``
    (grid indices of crossing pairs) and of the faces closest to the vertices ``x[inside]``."""
    if not len(crossed) and not len(inside):
        return np.zeros(0, dtype=np.int64)
    faces = around[crossed]
    if len(inside):
        faces = np.concatenate([faces, mesh.query(x[inside]).face])
    return np.unique(mesh.faces[faces].ravel())
