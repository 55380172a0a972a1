"""The mix-and-match pipeline (paper Figure 2, bottom row; docs/design.md section 1), no torch.

beta -> body mesh; explicit garment meshes X*_i(beta) in canonical space; every layer's fields at
every garment vertex; untangle; L-BFGS fit of each garment to its untangled field (``service.pipeline.fit``);
the diffused body displacement carries everything to the body (world space); collision handling
(``service.pipeline.collisions``: let-down and gathering at junctions, the squeeze and the exact repair,
which minimise the crossings the learned fields leave and report what is left); a quality report with
the measures of ``service.pipeline.quality`` before (explicit meshes), after the fit alone and after the
repair.

``OutfitModels`` loads everything once (it is what a server keeps); ``make_outfit`` is one request.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from service.geometry.closest import ClosestPoint
from service.pipeline.collisions import junctions
from service.pipeline.collisions.passes import repair_faults, resolve
from service.pipeline.collisions.settings import SETTINGS, CollisionSettings
from service.pipeline.collisions.squeeze import asks_segment_test
from service.pipeline.collisions.stack import Fitted, LayerFields, Stack
from service.pipeline.collisions.traits import traits_of
from service.pipeline.fields import BODY
from service.pipeline.fit import FitResult, FitSettings, fit_garment
from service.pipeline.models import OutfitModels, UntanglerKind
from service.pipeline.quality import Layer, intersections, penetration
from service.pipeline.strain import RestShape, green_strain_norms
from service.pipeline.untangle_onnx import N_SLOTS
from service.process.threads import pool

BodyFieldKind = Literal["exact", "neural"]
MAX_GARMENTS = N_SLOTS - 1
DEFAULT_FIT = FitSettings()


@dataclass
class Outfit:
    """World-space meshes (metres, Anny frame: Z up) and the quality report."""

    body_vertices: np.ndarray  # (Vb, 3)
    body_faces: np.ndarray
    garments: list[tuple[str, np.ndarray, np.ndarray]]  # (id, vertices (V, 3), faces (F, 3)), inner first
    report: dict = field(default_factory=dict)


FIT_THREADS = MAX_GARMENTS
"""Garments fitted side by side: all of a request's at once (the fits bit for bit the same). On 2 cores
``benchmarks.latency --compare`` against 2 threads: body + 3 and body + 4 garments 0.96 of the time
(a third fit no longer waits for a free thread), body + 1 and body + 2 unchanged."""


def _check_garments(models: OutfitModels, garment_ids: list[str]) -> None:
    if not 1 <= len(garment_ids) <= MAX_GARMENTS:
        raise ValueError(f"garments: between 1 and {MAX_GARMENTS} ids, got {len(garment_ids)}")
    unknown = [g for g in garment_ids if g not in models.catalog]
    if unknown:
        raise ValueError(f"garments: unknown ids {unknown}; allowed: {sorted(models.catalog)}")
    if len(set(garment_ids)) != len(garment_ids):
        raise ValueError(f"garments: each id at most once, got {garment_ids}")


def make_outfit(
    models: OutfitModels,
    garment_ids: list[str],
    beta: np.ndarray,
    untangle_layers: bool = True,
    untangler: UntanglerKind = "neural",
    settings: FitSettings = DEFAULT_FIT,
    measure: bool = True,
    body_field: BodyFieldKind = "exact",
    repair: bool = True,
    collisions: CollisionSettings = SETTINGS,
    body_vertices: np.ndarray | None = None,
    started: float | None = None,
    deltas: dict[str, np.ndarray] | None = None,
) -> Outfit:
    """Dress the body of shape ``beta (3,)`` in ``garment_ids`` (inner to outer); ``body_vertices (V, 3)``,
    when given, is the body instead (a shopper's own, ``body_build``), ``beta`` the code its garments
    take. ``deltas``: the garments worn in a size, each the size's delta ``(2,)`` on this body
    (``service.pipeline.size_model``); the others are the one-size garment cut to the body.

    With ``untangle_layers``: the field fit, then (``repair``) the exact repair of
    ``service.pipeline.collisions.repair``.
    """
    _check_garments(models, garment_ids)
    beta = np.asarray(beta, dtype=np.float64)
    seconds: dict[str, float] = {}
    t_total = t0 = time.perf_counter()
    body = models.body.vertices(beta) if body_vertices is None else np.asarray(body_vertices, float)
    seconds["body"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    # Each garment's explicit model and body clearance on its own thread (onnxruntime and the kernels
    # release the GIL); the same meshes as one after the other.
    deltas = deltas or {}
    # A sized garment's field is its one-size garment's (the fields take no size): its f is moved by
    # how far the size lies further out on average (SizeModel.lift), so the untangling sees the size.
    lifts: dict[str, float] = {}

    def explicit_mesh(g: str) -> np.ndarray:
        x = models.explicit[g].canonical(beta)
        if g in deltas:
            sized = models.sizes[g].canonical(x, beta, deltas[g])
            lifts[g] = models.sizes[g].lift(x, sized)
            x = sized
        return models.clearance.clear_of_body(x)

    unshifted = list(pool("fit", FIT_THREADS).map(explicit_mesh, garment_ids))
    faces = [models.catalog[g].faces for g in garment_ids]
    seconds["explicit"] = time.perf_counter() - t0
    # Where a garment was let down around an inner one and the repair still left crossings, the outfit
    # is made again with the next room below the junction (CollisionSettings.rooms): the usual orders, let
    # down nowhere, are made once, and so is every outfit that comes out clean. All attempts share one
    # budget of squeeze-and-repair passes (CollisionSettings.pass_budget): the bound on the worst case.
    how = _How(untangle_layers, untangler, settings, body_field, repair, collisions)
    attempts: list[_Attempt] = []
    passes_left = collisions.pass_budget
    # The request's clock (``started``: its ``time.perf_counter()``, the body's build before this
    # included) bounds its passes too (CollisionSettings.pass_seconds).
    deadline = (t_total if started is None else started) + collisions.pass_seconds
    for room in collisions.rooms:
        t0 = time.perf_counter()
        explicit, lowered = _let_down(models, garment_ids, unshifted, room)
        seconds["explicit"] += time.perf_counter() - t0
        meshes = (unshifted, explicit, lowered)
        attempt = _layered(models, garment_ids, beta, body, meshes, faces, seconds, how, passes_left,
                           deadline, lifts)  # fmt: skip
        attempts.append(attempt)
        passes_left -= attempt.passes
        late = time.perf_counter() > deadline
        if attempt.faults == (0, 0) or not any(lowered) or passes_left <= 0 or late:
            break
    chosen = min(attempts, key=lambda a: a.faults)  # the first of the fewest faults
    layer_ids = [BODY, *garment_ids]
    explicit, fits, fitted, fit_world, world, repairs = (
        chosen.explicit, chosen.fits, chosen.fitted, chosen.fit_world, chosen.world, chosen.repairs)
    outfit = Outfit(body, models.body.faces, list(zip(garment_ids, world, faces, strict=True)))
    report = {"garments": garment_ids, "beta": beta.tolist(), "untangled": untangle_layers}
    report["attempts"] = len(attempts)
    report["passes"] = sum(a.passes for a in attempts)
    if untangle_layers:
        report |= _fit_report(garment_ids, explicit, faces, fits, untangler)
    if repairs:
        # What a client checks: the returned meshes cross nothing and no vertex is left inside an inner
        # layer. False only for orders the repair could not make so (a jacket tucked into pants: its
        # front hangs below the crotch; docs/collisions.md).
        report["crossing_pairs"] = sum(r.crossing_pairs for r in repairs)
        report["collision_free"] = all(r.crossing_pairs == 0 and r.inside == 0 for r in repairs)
        report["repair"] = {
            g: {
                "moved_vertices": int(r.moved.sum()),
                "rounds": r.rounds,
                "crossing_pairs": r.crossing_pairs,
                "inside_vertices": r.inside,
            }
            for g, r in zip(garment_ids, repairs, strict=True)
        }
    if measure:
        t0 = time.perf_counter()
        before = models.space.to_bodies(explicit, body) if untangle_layers else world
        report |= _measures(models, layer_ids, body, beta, explicit, before, fitted, world, faces)
        if repairs:
            fit_only = _measures(models, layer_ids, body, beta, explicit, before, fitted, fit_world, faces)
            report["penetration_fit"] = fit_only["penetration_after"]
            report["intersections_fit"] = fit_only["intersections_after"]
        seconds["quality"] = time.perf_counter() - t0
    seconds["total"] = time.perf_counter() - t_total
    report["seconds"] = {k: round(v, 4) for k, v in seconds.items()}
    outfit.report = report
    return outfit


def _let_down(models: OutfitModels, garment_ids: list[str], unshifted: list[np.ndarray], room: float):
    """(canonical explicit meshes ``(V_i, 3)`` with every junction moved, per garment how far (m) its
    mesh moved) for the explicit meshes ``unshifted`` and ``room`` below each inner junction.

    An outer garment comes down around an inner one whose armhole or crotch hangs lower
    (``service.pipeline.collisions.junctions``, read on this body); a top tucked into a bottom whose crotch is
    higher than its hem is gathered up above it instead."""
    explicit = list(unshifted)
    lowered = [0.0] * len(garment_ids)
    around: list[set[int]] = []  # per garment, the inner garments it was let down around
    for j, garment in enumerate(garment_ids):
        # Each garment let down around the same inner one takes its own room below it: the outer of
        # two tops over a jacket comes down below the inner one's junction, not to it.
        drops = []
        for k, inner in enumerate(garment_ids[:j]):
            between = sum(k in around[m] for m in range(k + 1, j))
            drops.append(models.pairs.lowering(inner, garment, between, (unshifted[k], unshifted[j]), room))
        around.append({k for k, d in enumerate(drops) if d is not None})
        for k in range(j + 1, len(garment_ids)):  # read on this body: the bottom's crotch height
            gathering = models.pairs.raising(garment, garment_ids[k])
            drops.append(gathering and gathering.shift(explicit[j], explicit[k]))
        shift = junctions.combined([d for d in drops if d is not None])
        if shift is not None:
            explicit[j] = models.clearance.shifted_clear_of_body(explicit[j], shift)
            lowered[j] = float(np.abs(shift).max())
    return explicit, lowered


@dataclass
class _Attempt:
    """One try at the layering of an outfit (``make_outfit``): per garment its explicit mesh (junctions
    moved), fit, fitted canonical mesh, world mesh after the fit and after the repair, repair result."""

    explicit: list[np.ndarray]
    fits: list[FitResult]
    fitted: list[np.ndarray]
    fit_world: list[np.ndarray]
    world: list[np.ndarray]
    repairs: list
    passes: int = 0  # squeeze-and-repair passes run

    @property
    def faults(self) -> tuple[int, int]:
        """(crossing pairs, vertices inside) the repair left; (0, 0) without one."""
        return repair_faults(self.repairs)


@dataclass(frozen=True)
class _How:
    """``make_outfit``'s options for the fit and the repair."""

    untangle_layers: bool
    untangler: UntanglerKind
    settings: FitSettings
    body_field: BodyFieldKind
    repair: bool
    collisions: CollisionSettings


def _layered(
    models, garment_ids, beta, body, meshes, faces, seconds: dict, how: _How, pass_limit: int,
    deadline: float | None = None, lifts: dict[str, float] | None = None,
) -> _Attempt:
    """The fit, the body map and the repair of one ``_let_down``'s explicit meshes: ``meshes`` is (the
    explicit meshes before any junction moved them, after, how far each moved). The time of each stage
    is added to ``seconds``; the repair runs at most ``pass_limit`` passes, none starting after
    ``deadline`` but the first; ``lifts``: how far each sized garment's f moves out (``make_outfit``)."""
    unshifted, explicit, lowered = meshes
    untangle_layers, untangler, settings = how.untangle_layers, how.untangler, how.settings
    body_field, repair, collisions = how.body_field, how.repair, how.collisions
    layer_ids = [BODY, *garment_ids]

    def layer_fields(k, x, gradient):
        if k == 0 and body_field == "exact":
            return models.clearance.body_field(x, gradient)
        return _lifted(models.fields(layer_ids[k], x, beta, gradient), layer_ids[k], lifts)

    def add(key, value):
        seconds[key] = seconds.get(key, 0.0) + value

    fitted, fits = list(explicit), []
    if untangle_layers:
        t0 = time.perf_counter()
        op = models.untangler(untangler)
        # Where a vertex is provably far from a layer, its field is not asked (fit.FAR_FIELD): pants
        # and a jacket's sleeves.
        bounds = models.pairs.far_bounds(garment_ids, unshifted, explicit)

        def fit(i):
            return fit_garment(explicit[i], faces[i], i + 1, len(layer_ids), layer_fields, op, settings,
                               bounds[i])  # fmt: skip

        # The garments' fits are independent (each against the others' explicit fields): two at a time,
        # as numpy and onnxruntime release the GIL. The same fits as one after the other, bit for bit.
        fits = list(pool("fit", FIT_THREADS).map(fit, range(len(explicit))))
        fitted = [r.vertices if r.ok and np.all(np.isfinite(r.vertices)) else x0
                  for r, x0 in zip(fits, explicit, strict=True)]  # fmt: skip
        add("fit", time.perf_counter() - t0)
        # Per kind of work, summed over the garments (overlapping in time: they can add up to more
        # than "fit").
        for key in ("fields", "untangle", "optimise"):
            add(key, sum(r.seconds[key] for r in fits))
    t0 = time.perf_counter()
    world = models.space.to_bodies(fitted, body)
    add("world", time.perf_counter() - t0)
    fit_world, repairs, passes = world, [], 0
    if untangle_layers and repair:
        t0 = time.perf_counter()
        # Every layer's fields at every fitted vertex, as the fit left them (None: evaluate again).
        cache = [r.values if r.ok else None for r in fits]
        anchors = [models.pairs.anchors(g) for g in garment_ids]
        layer_fields_of = _fields_of(models, layer_ids, beta, lifts)
        stack = Stack(faces, anchors, _segment_test(models, garment_ids), layer_fields_of)
        body_mesh = ClosestPoint.build(body, models.body.faces)
        resolved = resolve(stack, body_mesh, explicit, Fitted(fitted, cache), world, lowered, collisions,
                           pass_limit, deadline)  # fmt: skip
        world, repairs, passes = resolved.meshes, resolved.repairs, resolved.passes
        add("repair", time.perf_counter() - t0)
    return _Attempt(explicit, fits, fitted, fit_world, world, repairs, passes)


def _fit_report(ids, explicit, faces, fits: list[FitResult], untangler: str) -> dict:
    out = {"untangler": untangler, "fallback": [g for g, r in zip(ids, fits, strict=True) if not r.ok]}
    for g, x0, f, r in zip(ids, explicit, faces, fits, strict=True):
        disp = np.linalg.norm(r.vertices - x0, axis=1)
        out.setdefault("mean_displacement_mm", {})[g] = round(float(disp.mean()) * 1e3, 3)
        out.setdefault("max_displacement_mm", {})[g] = round(float(disp.max()) * 1e3, 3)
        strain = green_strain_norms(r.vertices, r.rest or RestShape.build(x0, f))
        out.setdefault("mean_green_strain", {})[g] = round(float(strain.mean()), 6)
        out.setdefault("optimised_vertices", {})[g] = int(r.optimised.sum())
        out.setdefault("iterations", {})[g] = r.iterations
        # None where a network answered NaN (the fit then stopped; JSON has no NaN)
        ends = (r.residual_before, r.residual_after)
        residual = [round(v * 1e3, 3) if np.isfinite(v) else None for v in ends]
        out.setdefault("residual_mm", {})[g] = residual
    return out


def _measures(models, layer_ids, body, beta, explicit, before, fitted, world, faces) -> dict:
    out = {}
    for name, canonical, meshes in (("before", explicit, before), ("after", fitted, world)):
        layers = [Layer(BODY, body, models.body.faces)]
        layers += [Layer(g, v, f) for g, v, f in zip(layer_ids[1:], meshes, faces, strict=True)]

        def h_at(inner, outer, canonical=canonical):
            return models.fields(layer_ids[inner], canonical[outer - 1], beta).h

        def reversed_at(inner, layers=layers):
            v, f = layers[inner].vertices, layers[inner].faces
            return models.pairs.anchors(layer_ids[inner]).reversed_faces(v, f, body, models.body.faces)

        measured = penetration(layers, h_at, reversed_at)
        out[f"penetration_{name}"] = {k: round(v, 6) for k, v in measured.items()}
        out[f"intersections_{name}"] = intersections(layers)
    return out


def _fields_of(models: OutfitModels, layer_ids: list[str], beta: np.ndarray, lifts=None) -> LayerFields:
    """The stack's ``LayerFields``: layer k's (f, h) at canonical points, on the body ``beta``."""

    def fields(k: int, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        v = _lifted(models.fields(layer_ids[k], x, beta), layer_ids[k], lifts)
        return v.f, v.h

    return fields


def _lifted(values, layer_id: str, lifts: dict[str, float] | None):
    """``values`` (``FieldValues``) with f moved ``lifts[layer_id]`` outwards (f < 0 is inside)."""
    lift = (lifts or {}).get(layer_id, 0.0)
    return values._replace(f=values.f - lift) if lift else values


def _segment_test(models: OutfitModels, garment_ids: list[str]):
    """The stack's ``segment_test``: whether garment j under garment i asks the squeeze's segment test."""
    garments = [models.catalog[g] for g in garment_ids]
    rule = models.pairs.layering_rule()

    def asks(j: int, i: int) -> bool:
        return asks_segment_test(garments[j], garments[i], lambda g: traits_of(rule, g))

    return asks
