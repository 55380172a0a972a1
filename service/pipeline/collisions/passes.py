"""World-space untangling of the fitted outfit: the squeeze, then the exact repair, inner to outer.

``untangle_world`` runs ``collisions.squeeze`` (inner garments pressed under the outer ones that cover
them) and ``collisions.repair`` (every layer lifted clear of its final inner layers, exact crossing
tests) on the world meshes the fit and the body map produced, and repeats both where faults remain. Which
vertices can be near a layer, and where it covers them, comes from the fields at the fitted canonical vertices
(``_field_at``). ``models`` is a ``service.pipeline.outfit.OutfitModels``.
"""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import dataclass, field, fields, replace

import numpy as np

from service.geometry.closest import Closest, ClosestPoint
from service.geometry.fold_side import FoldSides
from service.geometry.kept_queries import KeptQueries, ask_ahead
from service.geometry.rings import dilate, vertex_neighbours
from service.pipeline.collisions.repair import REACH, Inner, RepairSettings, repair_layer
from service.pipeline.collisions.squeeze import Outer, SqueezeSettings, asks_segment_test, squeeze_layer
from service.pipeline.collisions.traits import traits_of

DEFAULT_SQUEEZE = SqueezeSettings()
ASK_AHEAD = True
"""Whether the squeeze and the repair ask closest points ahead, on a background thread (``ask_ahead``);
off, every query is asked when it is needed: the same meshes, bit for bit (tested)."""


@dataclass(frozen=True)
class Way:
    """How the passes after the first repeat the squeeze and the repair where faults are left."""

    from_repaired: bool
    """The next squeeze starts from this pass's repaired meshes (else from the fitted ones again, with only
    ``_deepen``'s depths carried over)."""
    squeeze: SqueezeSettings


WAYS = (Way(True, DEFAULT_SQUEEZE), Way(False, replace(DEFAULT_SQUEEZE, past_rim=True)))
"""Tried side by side, a pass of each in turn, until one comes out clean (``untangle_world``)."""
PASSES = 6
PASS_PATIENCE = 2
"""Passes of a way without fewer faults than its best before it stops."""
DEEPEN = 0.002
"""m: how much deeper, each pass, the squeeze presses an inner garment under an outer one where the repair
left them crossing (``_deepen``), up to ``DEEPEST``."""
DEEPEST = 0.008
DEEPEN_RING = 2
BODY_QUERY_PAD = 0.01
"""m: garment vertices the body's canonical distance puts farther out than the repair's largest margin
plus this are not asked for their
closest body points in the repair. World and canonical distances to the body differ by < 6 mm at 99 %
of garment vertices within 6 cm of 6 held-out bodies (one jacket vertex of 60,000: 38 mm, in an
armpit); a vertex missed that way still gets asked once a triangle of it is found crossing."""


def _field_at(models, layer_ids, beta, fitted, k: int, i: int):
    """Layer ``k``'s fields (f, h ``(V,)``) at garment ``i``'s fitted canonical vertices: from the fit's
    values where it left them, else evaluated (values only)."""
    vertices, cache = fitted
    if cache[i] is not None:
        return cache[i][0][:, k], cache[i][1][:, k]
    v = models.fields(layer_ids[k], vertices[i], beta)
    return v.f, v.h


def untangle_world(models, layer_ids, beta, body, explicit, fitted, world, faces, settings: RepairSettings,
                   lowered: list[float] | None = None):
    """The squeeze then the repair of the fitted world meshes; where faults are left, again, up to
    ``PASSES`` times in each of the ``WAYS``, a pass of each in turn, until one comes out clean.

    The first way squeezes the last pass's repaired meshes (the repair lifted an outer layer over an
    inner one that the squeeze can now press under it: four tops on a heavy body, 123 crossing pairs
    in the armpits after the first pass, 0 after the second). The second starts from the fitted meshes
    each time, pressed deeper where a pass of its own left faults, and does not pull cloth past an
    outer layer's rim: where the first way's passes pulled a jacket's cloth that lay past a T-shirt's
    armhole in by up to 10 cm, and made things worse pass after pass (58 -> 655 -> 2,437 crossing pairs),
    this one made jacket < shorts < long sleeve and long sleeve < jacket < T-shirt clean; it alone left
    the long sleeve in a skirt on the shortest man with 33, clean in the first. A way stops after
    ``PASS_PATIENCE`` passes without a new best of its own. Six passes, not three: a tank top under a
    jacket tucked into pants kept 13 pants vertices inside the jacket after three (0.17 %), 0.04 % after six;
    ``benchmarks.orders --pairs`` 114 -> 117 of 120 clean, ``--stacks 100`` 64 -> 65 of 85. Only
    outfits with faults left run past the first pass.

    Returns the meshes with the fewest crossings, then vertices inside, and their ``RepairResult``s.
    ``fitted`` is (fitted canonical vertices, the fits' field values or None) per garment
    (``_field_at``). ``lowered``: per garment, how far (m) its explicit mesh was let down from the one
    its fields were learned on (``collisions.junctions``), which widens where the garments over
    it look for it."""
    lowered = lowered or [0.0] * len(world)
    best = None
    body_mesh = ClosestPoint.build(body, models.body.faces)
    chains = [_Chain(way, world, [np.full(len(x), DEFAULT_SQUEEZE.margin) for x in world]) for way in WAYS]
    for _ in range(PASSES):
        for chain in chains:
            if chain.stale >= PASS_PATIENCE:
                continue
            squeezed = _squeeze(models, layer_ids, beta, fitted, chain.start, faces, body_mesh, chain.deep,
                                chain.pressed, chain.way.squeeze)  # fmt: skip
            meshes = (explicit, fitted, world, squeezed, faces)
            out, results = _repair(models, layer_ids, beta, body_mesh, *meshes, settings, lowered)
            # Crossings first: a vertex left inside an inner layer is within the quality bound (0.1 %)
            # long before a crossing pair is.
            faults = repair_faults(results)
            if best is None or faults < best[0]:
                best = (faults, out, results)
            if faults == (0, 0):
                return out, results
            chain.stale = 0 if faults < chain.fewest else chain.stale + 1
            chain.fewest = min(chain.fewest, faults)
            _deepen(results, faces, chain.deep, chain.pressed)
            chain.start = out if chain.way.from_repaired else world
    return best[1], best[2]


def repair_faults(results) -> tuple[int, int]:
    """(crossing pairs, vertices inside) left by an outfit's ``RepairResult``s: compared as a tuple,
    crossings first."""
    return (sum(r.crossing_pairs for r in results), sum(r.inside for r in results))


@dataclass
class _Chain:
    """One ``Way``'s passes: where its next squeeze starts, its per-vertex depths (``_deepen``), the
    fewest faults it reached and the passes since."""

    way: Way
    start: list[np.ndarray]
    deep: list[np.ndarray]
    pressed: dict = field(default_factory=dict)
    fewest: tuple = (np.inf, np.inf)
    stale: int = 0


def _deepen(results, faces, deep: list[np.ndarray], pressed: dict) -> None:
    """Where the repair left layer i crossing (or inside) garment k, the next squeeze presses k deeper
    under i: ``DEEPEN`` more margin (``deep[k] (V_k,)``, m) on the faults' vertices of k and
    ``DEEPEN_RING`` rings around them, and those vertices count as under i (``pressed[(k, i)] (V_k,)``
    bool) whatever i's fields say. Lifting i over k is all the repair can do, and over the gathered
    cloth of a jacket tucked into shorts it only trades 9 vertices inside for ~200 crossing pairs and
    back, pass after pass."""
    for i, r in enumerate(results):
        for n, at in enumerate(r.faults[1:]):  # the first inner layer is the body
            if not len(at):
                continue
            mask = np.zeros(len(deep[n]), dtype=bool)
            mask[at] = True
            mask = dilate(mask, vertex_neighbours(faces[n], len(mask)), DEEPEN_RING)
            deep[n][mask] = np.minimum(deep[n][mask] + DEEPEN, DEEPEST)
            pressed[(n, i)] = pressed.get((n, i), np.zeros(len(mask), dtype=bool)) | mask


def _squeeze(models, layer_ids, beta, fitted, world, faces, body: ClosestPoint, deep: list[np.ndarray],
             pressed: dict, squeeze: SqueezeSettings = DEFAULT_SQUEEZE) -> list[np.ndarray]:  # fmt: skip
    """World meshes with every garment pulled inside the outer ones that cover it
    (``collisions.squeeze``), from the outermost inwards. Where an outer garment covers a vertex and how
    far it is comes from the outer garment's fields at the vertex's fitted canonical position, as in
    ``_repair``, and from ``_deepen``'s ``pressed``; how far inside it goes, from its ``deep``.

    Garment i's mesh is final once its own squeeze is done (the outermost's from the start): the first
    closest points of the garments two or more layers under it are asked ahead then (``ask_ahead``),
    while the garments between are squeezed."""
    out = list(world)
    meshes: dict[int, ClosestPoint] = {}
    # (j, i): garment j's vertices near outer garment i and covered by it, where any are
    masks = {}
    for j in range(len(out) - 1):
        for i in range(j + 1, len(out)):
            f, h = _field_at(models, layer_ids, beta, fitted, i + 1, j)
            near, covered = np.abs(f) < REACH, h < 0
            if (j, i) in pressed:
                near, covered = near | pressed[(j, i)], covered | pressed[(j, i)]
            if (near & covered).any():
                masks[(j, i)] = (near, covered)
    asked: dict[tuple[int, int], tuple[KeptQueries, Future]] = {}

    def mesh(i: int) -> ClosestPoint:
        if i not in meshes:
            meshes[i] = ClosestPoint.build(out[i], faces[i])
        return meshes[i]

    def ahead(i: int) -> None:
        """Garment i's mesh is final: ask it about the garments two or more under it, nearest first."""
        for j in range(i - 2, -1, -1) if ASK_AHEAD else ():
            if (j, i) in masks:
                near, covered = masks[(j, i)]
                kept = KeptQueries(mesh(i), len(out[j]))
                asked[(j, i)] = (kept, ask_ahead(kept, out[j], np.flatnonzero(near & covered)))

    ahead(len(out) - 1)
    for j in range(len(out) - 2, -1, -1):
        outer = []
        for i in range(j + 1, len(out)):
            if (j, i) not in masks:
                continue
            kept = None
            if (j, i) in asked:
                kept, future = asked.pop((j, i))
                future.result()
            inner_g, outer_g = models.catalog[layer_ids[j + 1]], models.catalog[layer_ids[i + 1]]
            looser = asks_segment_test(inner_g, outer_g, lambda g: traits_of(models.layering_rule(), g))
            outer.append(Outer(mesh(i), *masks[(j, i)], looser_under=looser, kept=kept))
        if outer:
            floor = (j + 1) * DEFAULT_SQUEEZE.margin  # room for the garments under this one
            looser = any(o.looser_under for o in outer)  # else the segment test is never asked
            anchors = models.anchors(layer_ids[j + 1]).on(body.vertices, body.faces) if looser else None
            r = squeeze_layer(out[j], faces[j], outer, body, floor, squeeze, anchors, deep[j])
            out[j] = r.vertices if np.all(np.isfinite(r.vertices)) else out[j]
        ahead(j)
    return out


def _repair(models, layer_ids, beta, body: ClosestPoint, explicit, fitted, fit_world, world, faces, settings,
            lowered):
    """Repaired world meshes and their ``RepairResult``s, each layer against the final inner ones.

    Which vertices can be near an inner layer, and where it covers them, comes from the fields at the
    layer's fitted canonical vertices (``_field_at``: those the fit left, values only). The
    fields are those of the explicit meshes: an inner garment that its fit and repair moved by up to
    s is looked for within ``REACH`` + s. The fields were read where the fit left a vertex: one the
    squeeze (or an earlier pass) moved by d since is looked for within d more, so that the crossings
    left that the repair counts are never fewer than the returned meshes have (a loose sleeve walked
    5 cm to its anchor can end inside the arm)."""
    inner = [(body, True, 0.0, None, None)]
    out, results = [], []
    # The body never moves, and every layer's first pushes ask it about the layer's vertices where
    # the squeeze left them: those queries go in one batch, which the query's blocks spread over both
    # cores (a layer's own batch is often below a block); the same answers, kept for each layer.
    masks = []
    # m per vertex: how far the squeeze (and an earlier pass) moved it from where the fit left it.
    own = [np.linalg.norm(x - x0, axis=1) for x, x0 in zip(world, fit_world, strict=True)]
    for i in range(len(world)):
        # The body's distance is exact (canonical, a grid): only vertices it puts within
        # max_margin + BODY_QUERY_PAD can be within a margin of the body in world space, less how far
        # they moved since the fit: a jacket's sleeve walked 5 cm to its anchor on the arm can be
        # inside the arm.
        f_body = _field_at(models, layer_ids, beta, fitted, 0, i)[0] - own[i]
        masks.append((f_body < REACH, f_body < settings.max_margin + BODY_QUERY_PAD))
    kept_body = _asked_together(body, world, [np.flatnonzero(near & query) for near, query in masks])
    # (i, k): garment i's Inner for inner layer k (a garment), asked ahead (``ask_ahead``) once layer k
    # was final, while the garments between were repaired, and the future its first answers come from.
    asked: dict[tuple[int, int], tuple[Inner, Future]] = {}

    def garment_inner(i: int, k: int) -> Inner:
        """Layer k (a garment under garment i, final) as garment i's repair sees it."""
        mesh, _, moved, turned, sides = inner[k]
        f_k, h_k = _field_at(models, layer_ids, beta, fitted, k, i)
        near = np.abs(f_k) < REACH + moved + own[i]
        return Inner(mesh, False, near, h_k < 0, reversed_faces=turned, sides=sides)

    for i, (x, f) in enumerate(zip(world, faces, strict=True)):
        layers = []
        for k, (mesh, closed, *_) in enumerate(inner):
            if closed:
                near, query = masks[i]
                layers.append(Inner(mesh, True, near, np.ones(len(x), dtype=bool), query, kept_body[i]))
            elif (i, k) in asked:
                layer, future = asked.pop((i, k))
                future.result()
                layers.append(layer)
            else:
                layers.append(garment_inner(i, k))
        r = repair_layer(x, f, layers, settings)
        out.append(r.vertices if np.all(np.isfinite(r.vertices)) else x)
        results.append(r)
        # How far this layer now is from its explicit mesh, whose fields the outer layers see: the fit
        # moved it in canonical space (x 1.2 for the stretch of the body map), the squeeze and the
        # repair in world space.
        fit_move = float(np.linalg.norm(fitted[0][i] - explicit[i], axis=1).max())
        moved = 1.2 * fit_move + float(np.linalg.norm(out[-1] - fit_world[i], axis=1).max())
        moved += 1.2 * lowered[i]  # its fields are of the mesh before it was let down
        if i == len(world) - 1:
            break  # no layer over it
        # Its faces turned against the body, the same for every layer over it.
        anchors = models.anchors(layer_ids[i + 1])
        turned = anchors.reversed_faces(out[-1], f, body.vertices, body.faces, body.fn)
        # Their side where those faces are closest is the measure's crossing parity (``fold_side``).
        sides = FoldSides.build(out[-1], f, body, settings.band)
        inner.append((ClosestPoint.build(out[-1], f), False, moved, turned, sides))
        # Its closest points for the garments two or more over it, nearest first, while the ones between
        # are repaired: their first round asks every near vertex, where the squeeze left it.
        k = len(inner) - 1
        for later in range(i + 2, len(world)) if ASK_AHEAD else ():
            layer = garment_inner(later, k)
            layer.kept = KeptQueries(layer.mesh, len(world[later]), layer.reversed_faces, layer.sides)
            asked[(later, k)] = (layer, ask_ahead(layer.kept, world[later], np.flatnonzero(layer.near)))
    return out, results


def _asked_together(
    mesh: ClosestPoint, point_sets: list[np.ndarray], asked: list[np.ndarray]
) -> list[KeptQueries]:
    """``KeptQueries`` of ``mesh`` for each of ``point_sets (V_i, 3)`` holding the answers for its points
    ``asked[i] (K_i,)``, all asked in one query."""
    kept = [KeptQueries(mesh, len(x)) for x in point_sets]
    total = sum(len(a) for a in asked)
    if not total:
        return kept
    q = mesh.query(np.concatenate([x[a] for x, a in zip(point_sets, asked, strict=True)]))
    start = 0
    for x, a, k in zip(point_sets, asked, kept, strict=True):
        part = slice(start, start + len(a))
        k.store(x, a, Closest(*(getattr(q, name.name)[part] for name in fields(Closest))))
        start += len(a)
    return kept
