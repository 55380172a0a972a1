"""A body that overlaps itself, pressed into contact: thighs, breasts and belly folds of heavy bodies.

Anny's extrapolated weight and girth changes (``service.pipeline.body``, decision 0020) grow each part
of the body on its own, so the inner thighs of women from BMI ~32-38 and the chest folds of men from
BMI ~43-47 (``models/body/body_table.npz``'s ``crossings``), and the breasts, belly folds and armpits of
the heaviest, pass through each other. Flesh does not: it presses flat where two parts meet.
``press_contacts`` does that to the mesh, in rounds until nothing crosses:

- where two triangles of different parts cross, each corner behind the other triangle's plane moves out
  along that plane's normal by half its depth plus half of ``gap`` (both sides give way alike, as two
  soft bodies do), at most ``STEP``; the moves are spread over the neighbours (``SPREAD_RINGS``) so the
  contact is a smooth flat, not a step;
- two crossing triangles a few rings apart on the surface (``FOLD_RINGS``) are one sheet folded (a
  crumpled armpit), not two parts: they are not pushed;
- the crossing triangles and a ring around them are relaxed (``RELAX``), which unfolds those folds and
  the crease the pushes leave where two parts join (the crotch).

The body stays one closed, non-self-intersecting surface for the fields, the garments and the tape,
and loses the overlap its volume counted twice (its weight is solved again on the pressed mesh:
``service.pipeline.body_build.pressed_body``).

``self_crossings`` is the test, through ``TriangleGrid`` (compiled); ``intersecting_pairs`` with no
second mesh is its reference (the same pairs, tested).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix, identity

from service.geometry.intersections import TriangleGrid
from service.geometry.mesh import face_normals
from service.geometry.rings import dilate, vertex_neighbours

SPREAD_RINGS = 2
"""Rings of neighbours a pushed vertex's move is spread over (averaged into the vertices not pushed), so
the contact is a smooth flat rather than a step at the crossing curve (looked at on the heavy bodies of
docs/images/self_contact.png)."""
STEP = 0.002
"""m: the most a vertex moves in one round. Unbounded, the first round moved a BMI 65 woman's vertices by
up to 29 mm (planes of steep triangles) and the crossings grew round after round."""
RELAX_STEPS = 1
RELAX = 0.5
"""Umbrella steps per round over the crossing triangles and one ring around them, and their weight:
without them the crotch kept a pinched crease that crossed round after round (a BMI 40 woman: 68 -> 36
crossings after 15 rounds; with one half step: 0 after 7)."""
FOLD_RINGS = 4
"""Crossing triangles whose corners are within this many rings of each other on the surface are a fold
of one sheet: relaxed, not pushed (a BMI 60 woman's armpits kept 14 such crossings through 40 rounds
of pushing; 0 after 16 rounds without)."""
MAX_ROUNDS = 40
"""Rounds of ``press_contacts``: held-out NHANES women of BMI 40-65 close in 7-16 rounds; the rest is
headroom, and a body still crossing after them is reported (``Pressed.crossings``), not looped on."""


def self_crossings(
    vertices: np.ndarray, faces: np.ndarray, ignore: np.ndarray | None = None, only: np.ndarray | None = None
) -> np.ndarray:
    """Pairs ``(K, 2)`` (i < j) of triangles of one mesh that cross, pairs sharing a vertex skipped:
    ``intersecting_pairs(vertices, faces)``, through the compiled grid. ``ignore (F,) bool``, when given,
    drops every pair with a face it marks (a template's own crossings: Anny's toes); ``only (F,) bool``
    keeps the pairs with a face it marks (those near what moved), and tests no other."""
    grid = TriangleGrid.build(vertices, faces)
    if only is None:
        pairs = grid.crossing(vertices, faces)
    else:
        tested = np.flatnonzero(only)
        found = grid.crossing(vertices, faces[tested])
        pairs = np.stack([tested[found[:, 0]], found[:, 1]], axis=1)
        pairs = np.unique(np.sort(pairs, axis=1), axis=0) if len(pairs) else pairs
    pairs = pairs[pairs[:, 0] < pairs[:, 1]]
    shared = (faces[pairs[:, 0], :, None] == faces[pairs[:, 1], None, :]).any(axis=(1, 2))
    pairs = pairs[~shared]
    if ignore is not None and len(pairs):
        pairs = pairs[~(ignore[pairs[:, 0]] | ignore[pairs[:, 1]])]
    return pairs


def _pushes(vertices, faces, pairs, n_face, gap) -> tuple[np.ndarray, np.ndarray]:
    """For each corner of a crossing pair's triangle that lies behind the other triangle's plane: its
    vertex id ``(M,)`` and the push ``(M, 3)`` out along that plane's normal by half its depth plus half
    of ``gap`` (a vertex may repeat)."""
    idx, push = [], []
    for a, b in ((0, 1), (1, 0)):
        fa, fb = pairs[:, a], pairs[:, b]
        v = faces[fa]  # (K, 3) vertex ids of the triangles whose corners may sink
        p = vertices[faces[fb, 0]]  # (K, 3) a point of the other plane
        d = -np.einsum("kcj,kj->kc", vertices[v] - p[:, None, :], n_face[fb])  # (K, 3) depth behind it
        behind = d > 0
        k = np.nonzero(behind)[0]
        idx.append(v[behind])
        push.append(np.minimum(0.5 * (d[behind] + gap), STEP)[:, None] * n_face[fb][k])
    return np.concatenate(idx), np.concatenate(push)


def _near_on_surface(adjacency, a: np.ndarray, b: np.ndarray, rings: int) -> np.ndarray:
    """``(K,) bool``: vertex ``a[k]`` within ``rings`` rings of ``b[k]`` (``adjacency (V, V)``)."""
    n = adjacency.shape[0]
    reach = csr_matrix((np.ones(len(a)), (np.arange(len(a)), a)), shape=(len(a), n))
    step = identity(n, format="csr") + adjacency
    for _ in range(rings):
        reach = reach @ step
    return np.asarray(reach[np.arange(len(a)), b]).ravel() > 0


class Pressed:
    """What ``press_contacts`` did: ``vertices (V, 3)``, ``rounds`` run, ``crossings`` left (0 unless
    the rounds ran out), ``moved`` vertices and the largest move ``max_move`` (m)."""

    def __init__(self, vertices, rounds, crossings, moved, max_move):
        self.vertices, self.rounds, self.crossings = vertices, rounds, crossings
        self.moved, self.max_move = moved, max_move


def press_contacts(
    vertices: np.ndarray,
    faces: np.ndarray,
    gap: float,
    ignore: np.ndarray | None = None,
    max_rounds: int = MAX_ROUNDS,
) -> Pressed:
    """``vertices (V, 3)`` of a closed mesh ``faces (F, 3)`` whose parts cross each other, pressed into
    contact ``gap`` (m) apart (module docstring). ``ignore (F,) bool``: crossings left as they are.
    Returns ``Pressed``; a mesh that does not cross itself comes back unchanged, 0 rounds."""
    x = np.array(vertices, dtype=np.float64)
    start = x.copy()
    adjacency = vertex_neighbours(faces, len(x))
    degree = np.maximum(np.asarray(adjacency.sum(axis=1)).ravel(), 1.0)
    total = np.zeros(len(x))
    rounds = 0
    pairs = self_crossings(x, faces, ignore)
    while len(pairs) and rounds < max_rounds:
        rounds += 1
        # Two triangles a few edges apart that cross are one sheet folded (a crumpled armpit), not two
        # parts meeting: pushing them along each other's normals only folds it tighter; relaxing smooths.
        meeting = ~_near_on_surface(adjacency, faces[pairs[:, 0], 0], faces[pairs[:, 1], 0], FOLD_RINGS)
        idx, push = _pushes(x, faces, pairs[meeting], face_normals(x, faces), gap)
        move = np.zeros_like(x)
        count = np.zeros(len(x))
        np.add.at(move, idx, push)
        np.add.at(count, idx, 1.0)
        move /= np.maximum(count, 1.0)[:, None]
        # Spread: each ring averages its neighbours' moves into the vertices that have none.
        for _ in range(SPREAD_RINGS):
            still = count == 0
            spread = (adjacency @ move) / degree[:, None]
            move[still] = spread[still]
            count[still] = (adjacency @ (count > 0).astype(float))[still]
        x += move
        total += np.linalg.norm(move, axis=1)
        # Relax the pressed region (umbrella steps): where two folds of one sheet meet (the crotch,
        # the armpit) the pushes alone pinch a crease that keeps crossing.
        crossing = np.zeros(len(x), dtype=bool)
        crossing[faces[pairs].ravel()] = True
        region = dilate(crossing, adjacency, 1)
        for _ in range(RELAX_STEPS):
            mean = (adjacency @ x) / degree[:, None]
            x[region] += RELAX * (mean[region] - x[region])
        # Only triangles near what moved can cross anew (a quarter of the time); the whole mesh is
        # tested before stopping.
        near = dilate(np.any(x != start, axis=1), adjacency, 1)
        pairs = self_crossings(x, faces, ignore, only=near[faces].any(axis=1))
        if not len(pairs):
            pairs = self_crossings(x, faces, ignore)
    moved = int(np.count_nonzero(total))
    return Pressed(x, rounds, len(pairs), moved, float(total.max()) if len(total) else 0.0)
