"""The mix-and-match pipeline (paper Figure 2, bottom row; docs/design.md section 1), no torch.

beta -> body mesh; explicit garment meshes X*_i(beta) in canonical space; every layer's fields at
every garment vertex; untangle; L-BFGS fit of each garment to its untangled field (``service.pipeline.fit``);
the diffused body displacement carries everything to the body (world space); the squeeze and the
exact repair of ``service.pipeline.collisions.passes`` (the learned fields are millimetres off the meshes: the
repair makes the returned meshes meet the measures exactly); a quality report with the measures of
``service.pipeline.quality`` before (explicit meshes), after the fit alone and after the repair.

``OutfitModels`` loads everything once (it is what a server keeps); ``make_outfit`` is one request.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from service.geometry.anchors import BodyAnchors
from service.geometry.closest import ClosestPoint, signed_distance
from service.geometry.sdf_grid import SdfGrid
from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.canonical import CanonicalSpace
from service.pipeline.catalog import Garment, load_catalog
from service.pipeline.collisions import junctions
from service.pipeline.collisions.layering import GarmentProfile, LayeringRule, Refusal
from service.pipeline.collisions.passes import repair_faults, untangle_world
from service.pipeline.collisions.repair import RepairSettings
from service.pipeline.collisions.traits import traits_of, tucked
from service.pipeline.explicit import ExplicitModel, ExplicitOnnx
from service.pipeline.fields import BODY, FieldSet, FieldValues
from service.pipeline.fit import FitResult, FitSettings, fit_garment
from service.pipeline.quality import Layer, intersections, penetration
from service.pipeline.strain import RestShape, green_strain_norms
from service.pipeline.untangle import untangle_with_jacobian
from service.pipeline.untangle_onnx import N_SLOTS, NeuralUntangler
from service.process.threads import pool

UntanglerKind = Literal["neural", "reference"]
BodyFieldKind = Literal["exact", "neural"]
MAX_GARMENTS = N_SLOTS - 1
CLEARANCE = 5e-4  # m: explicit vertices closer to the body than this move out to it (training.drape's)
SHIFT_STEP = 0.01
"""m: the longest move of a let-down or gathered garment's vertex between two clearings of the body
(``OutfitModels.shifted_clear_of_body``): well under an arm's or a wrist's radius (2.5 cm and more)."""
GAP_STEP = 0.004
"""m: the kept ``OutfitModels.gap`` is rounded down to this (a byte a vertex, up to 1.02 m): a lower
bound stays one, 4 mm looser at most, against ``fit.FAR_FIELD``'s 8 cm."""
DEFAULT_FIT = FitSettings()
DEFAULT_REPAIR = RepairSettings()


@dataclass
class OutfitModels:
    """Everything a request needs, loaded once."""

    body: BodyModel
    catalog: dict[str, Garment]
    explicit: dict[str, ExplicitModel | ExplicitOnnx]
    fields: FieldSet
    neural_untangler: NeuralUntangler
    space: CanonicalSpace
    body_sdf: SdfGrid | None = None
    layering: LayeringRule | None = None
    _anchors: dict = field(default_factory=dict, repr=False)
    """Which orders cloth can take (``service.pipeline.collisions.layering``); made on first use when None."""
    _junctions: dict = field(default_factory=dict, repr=False)
    _drapes: dict = field(default_factory=dict, repr=False)
    _gaps: dict = field(default_factory=dict, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def layering_rule(self) -> LayeringRule:
        if self.layering is None:
            self.layering = LayeringRule(self.space.mean_vertices, self.space.faces)
        return self.layering

    def anchors(self, layer_id: str) -> BodyAnchors:
        """Where the garment's vertices sit on the body (``collisions.squeeze``), made once."""
        if layer_id not in self._anchors:
            self._anchors[layer_id] = BodyAnchors.build(self.catalog[layer_id].vertices, self.space.closest)
        return self._anchors[layer_id]

    def lowering(self, inner_id: str, outer_id: str, between: int = 0,
                 on: tuple[np.ndarray, np.ndarray] | None = None,
                 extra: float = junctions.EXTRA) -> np.ndarray | None:  # fmt: skip
        """The canonical displacement (V, 3) that lets ``outer_id``'s junctions down below
        ``inner_id``'s (``collisions.junctions``), or None where their drapes on the mean body
        have no junction run. ``between``: garments between the two let down around ``inner_id`` too.
        ``on``: the two garments' explicit meshes on the body they are worn on (canonical, before any
        junction moved them): the drop is then that body's (``junctions.body_run``, 25-45 ms a pair in
        a one-off timing), as every request asks; else the mean body's, made on first use (~1 ms).
        ``extra``: the room below the inner junction (``junctions.ROOMS``)."""
        if self._junction(inner_id, outer_id)[1] is None:
            return None
        if on is None and between == 0 and extra == junctions.EXTRA:
            return self._junction(inner_id, outer_id)[1]
        with self._lock:  # made by _junction
            (_, inner), (drape, outer) = (self._drape_profile(g) for g in (inner_id, outer_id))
        body, length = self.layering_rule().body, None
        if on is not None:
            faces = (self.catalog[inner_id].faces, self.catalog[outer_id].faces)
            length = junctions.body_run(inner, outer, body, on[0], faces[0], on[1], faces[1])
        return junctions.lowering(inner, outer, body, drape, between, length, extra)

    def raising(self, inner_id: str, outer_id: str) -> junctions.Gathering | None:
        """How a top tucked into ``outer_id`` is gathered up above its crotch (``junctions.raising``), or
        None; made and kept as ``lowering``. A top in a bottom is raised, never the bottom let down."""
        return self._junction(inner_id, outer_id)[0]

    def _junction(self, inner_id: str, outer_id: str):
        """(the inner garment's raising, the outer garment's lowering) of an ordered pair, kept."""
        key = (inner_id, outer_id)
        with self._lock:  # two requests' threads may ask for the same pair at once
            if key not in self._junctions:
                (inner_drape, inner), (drape, outer) = (self._drape_profile(g) for g in key)
                body = self.layering_rule().body
                a, b = self.catalog[inner_id], self.catalog[outer_id]
                rule = self.layering_rule()
                tucked_in = tucked(traits_of(rule, a), traits_of(rule, b))  # a top in a bottom
                up = junctions.raising(inner, outer, body, inner_drape, a.faces, drape) if tucked_in else None
                down = None if up is not None else junctions.lowering(inner, outer, body, drape)
                self._junctions[key] = (up, down)
            return self._junctions[key]

    def gap(self, garment_id: str, other_id: str) -> np.ndarray:
        """``(V,)`` m: how far each vertex of ``garment_id``'s drape on the mean body is from
        ``other_id``'s drape there, in canonical space, rounded down to ``GAP_STEP``: made on first
        use (~20 ms) and kept in a byte a vertex (an imported catalog of 50 garments: 2,450 ordered
        pairs, 25 MB)."""
        key = (garment_id, other_id)
        with self._lock:
            if key not in self._gaps:
                (x, _), (y, _) = self._drape_profile(garment_id), self._drape_profile(other_id)
                d = ClosestPoint.build(y, self.catalog[other_id].faces).query(x).distance
                self._gaps[key] = np.minimum(np.floor(d / GAP_STEP), 255).astype(np.uint8)
            return self._gaps[key] * GAP_STEP

    def far_bounds(self, garment_ids: list[str], unshifted: list[np.ndarray], explicit: list[np.ndarray]):
        """Per garment, ``(V, N)`` lower bounds (m) on the distance from each of its explicit vertices
        ``explicit[i]`` to each layer's surface on this body (``fit_garment``'s ``bounds``; 0 for the
        body and the garment itself). ``unshifted``: the explicit meshes before the junctions moved
        them, as the fields know them. A vertex is as far from the other garment's mean drape as
        ``gap`` says, less how far it is from its own mean drape, less how far the other garment's
        mesh is, at most, from its mean drape (the distance to a mesh changes no faster than the
        point or the mesh moves)."""
        with self._lock:
            drapes = [self._drape_profile(g)[0] for g in garment_ids]
        spread = [float(np.linalg.norm(u - d, axis=1).max()) for u, d in zip(unshifted, drapes, strict=True)]
        out = []
        for i, (g, x) in enumerate(zip(garment_ids, explicit, strict=True)):
            bounds = np.zeros((len(x), len(garment_ids) + 1))
            own = np.linalg.norm(x - drapes[i], axis=1)
            for k, other in enumerate(garment_ids):
                if k != i:
                    bounds[:, k + 1] = np.maximum(self.gap(g, other) - own - spread[k], 0.0)
            out.append(bounds)
        return out

    def warm(self) -> None:
        """Make up front what requests would make on first use: the layering rule's profiles and every
        garment's drape profile (~60 ms a garment) and every ordered pair of bundled garments' ``gap``
        (~12 ms a pair); a pair's lowering is then ~1 ms, made when asked."""
        self.layering_rule().warm(self.catalog.values())
        with self._lock:
            for garment_id in self.catalog:
                self._drape_profile(garment_id)
        # The bundled garments' pairs (42, 0.5 s); an imported garment's are made on first use, so
        # that start-up does not grow with the square of the catalog.
        bundled = [g for g, garment in self.catalog.items() if garment.origin == "bundled"]
        for g in bundled:
            for other in bundled:
                if g != other:
                    self.gap(g, other)

    def _drape_profile(self, garment_id: str) -> tuple[np.ndarray, GarmentProfile]:
        """(the garment's drape on the mean body (V, 3), canonical; its slices' profile), kept."""
        if garment_id not in self._drapes:
            beta = np.asarray(DEFAULT_BETA, dtype=np.float64)
            drape = self.clear_of_body(self.explicit[garment_id].canonical(beta))
            body = self.layering_rule().body
            profile = GarmentProfile.build(garment_id, drape, self.catalog[garment_id].faces, body)
            self._drapes[garment_id] = (drape, profile)
        return self._drapes[garment_id]

    def refusals(self, garment_ids: list[str]) -> list[Refusal]:
        """Why cloth cannot take the order ``garment_ids`` (inner to outer): empty when it can."""
        return self.layering_rule().refusals([self.catalog[g] for g in garment_ids])

    def body_field(self, x: np.ndarray, gradient: bool) -> FieldValues:
        """The body's signed distance in canonical space, where every body is the mean body: the
        committed grid of its exact distance (``service.geometry.sdf_grid``, ~0.1 mm off), or the exact
        closest-point query without it (the learned body field is 1.3 mm off, a third of the gap)."""
        h = np.full(len(x), -1.0)
        if self.body_sdf is not None:
            f, grad = self.body_sdf(x, self.exact_body_distance)
        else:
            f, grad = self.exact_body_distance(x)
        return FieldValues(f, h, grad, np.zeros_like(x)) if gradient else FieldValues(f, h, None, None)

    def clear_of_body(self, x: np.ndarray) -> np.ndarray:
        """Canonical vertices ``x (V, 3)`` with those inside the mean body, or within ``CLEARANCE`` of
        it, moved out along the distance gradient to ``CLEARANCE`` (the drape dataset's own rule).
        The body-offset explicit models stay above the body's tangent plane at each vertex's anchor,
        which a concave patch (a wrist by the hip, ~0.4 % of a jacket on a short heavy body) still
        lets a few vertices sink through; canonical distance is world distance, so this keeps them
        out of every body."""
        # The grid finds the few candidates (it is up to ~1.6 mm off at the face and the feet); the
        # exact distance moves them, a step or two (one lands within the surface's curvature error).
        ask = np.flatnonzero(self.body_field(x, gradient=False).f < CLEARANCE + 0.003)
        out = x
        for _ in range(3):
            if not len(ask):
                break
            f, grad = self.exact_body_distance(out[ask])
            low = f < 0.9 * CLEARANCE
            out = out.copy() if out is x else out
            ask = ask[low]
            out[ask] += (CLEARANCE - f[low])[:, None] * grad[low]
        return out

    def shifted_clear_of_body(self, x: np.ndarray, shift: np.ndarray) -> np.ndarray:
        """``clear_of_body(x + shift)`` for canonical vertices ``x (V, 3)`` and a lowering or raising
        ``shift (V, 3)``, moved in steps of at most ``SHIFT_STEP``, each cleared of the body.

        A drop of 20-26 cm (a T-shirt over a long sleeve over a jacket) takes a sleeve's underside
        through the arm in one move; cleared once, each vertex inside went out of the arm at its
        nearest side, some below it and some back above it, and the sleeve tore into spikes (strain 6
        -> 76 on one held-out body, 492 vertices moved 2-4 cm by the clearing; the spikes crossed the
        body and both inner tops). In steps shorter than an arm's radius a vertex meets the arm's
        surface from above and stays on it, as cloth pulled down over an arm does."""
        moving = np.flatnonzero(np.any(shift != 0, axis=1))
        steps = int(np.ceil(np.abs(shift).max() / SHIFT_STEP)) if len(moving) else 0
        if steps <= 1:
            return self.clear_of_body(x + shift)
        part, delta = x[moving], shift[moving] / steps
        for _ in range(steps):
            part = self.clear_of_body(part + delta)
        out = x.copy()
        out[moving] = part
        return out

    def exact_body_distance(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(signed distance (P,), gradient (P, 3)) to the mean body by closest-point query."""
        return signed_distance(self.space.closest, x)

    @classmethod
    def load(cls, directory: Path | None = None, threads: int = 2, imported: list[Path] = ()) -> OutfitModels:
        """The models of ``directory`` (default ``models_dir()``) plus the garments of each
        ``imported`` directory (``garments/``, ``explicit/``, ``fields/``: an imported garment's,
        ``service.pipeline.catalog.imported_garment_dirs``)."""
        from service.process.paths import models_dir
        from service.process.tuning import tune_process

        tune_process()
        directory = Path(directory or models_dir())
        body = BodyModel.load(directory / "body" / "anny_shape.npz")
        catalog = dict(load_catalog(directory / "garments"))
        explicit = {gid: ExplicitOnnx(gid, directory / "explicit") for gid in catalog}
        fields = FieldSet(directory / "fields", threads)
        for extra in imported:
            garments = load_catalog(Path(extra) / "garments", origin="imported")
            taken = sorted(set(garments) & set(catalog))
            if taken:
                raise ValueError(f"{extra}: garment ids {taken} are already in the catalog")
            catalog |= garments
            explicit |= {gid: ExplicitOnnx(gid, Path(extra) / "explicit") for gid in garments}
            fields.add(Path(extra) / "fields")
        return cls(
            body, catalog, explicit, fields,
            NeuralUntangler(directory / "untangler", threads),
            CanonicalSpace.build(body.vertices(np.asarray(DEFAULT_BETA)), body.faces, threads),
            SdfGrid.load(sdf) if (sdf := directory / "body" / "mean_sdf.npz").exists() else None,
        )  # fmt: skip

    def untangler(self, kind: UntanglerKind):
        """The operator as ``service.pipeline.fit.Untangler``: (f, Jacobian (P, N, 2N), only its row k (P, 1,
        2N) when called with ``row=k``, or None)."""
        from service.pipeline.fit import rows_of

        if kind == "neural":

            def neural(f_star, h_star, jacobian, row=None):
                out = self.neural_untangler.screened(f_star, h_star, jacobian=jacobian, row=row)
                return out.f, out.jacobian

            neural.h_band = self.neural_untangler.h_band  # it sees h* only through clamp(h* / h_band)
            return neural

        return rows_of(untangle_with_jacobian)


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
    repair_settings: RepairSettings = DEFAULT_REPAIR,
) -> Outfit:
    """Dress the body of shape ``beta (3,)`` in ``garment_ids`` (inner to outer).

    With ``untangle_layers``: the field fit, then (``repair``) the exact repair of
    ``service.pipeline.collisions.repair``.
    """
    _check_garments(models, garment_ids)
    beta = np.asarray(beta, dtype=np.float64)
    seconds: dict[str, float] = {}
    t_total = t0 = time.perf_counter()
    body = models.body.vertices(beta)
    seconds["body"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    # Each garment's explicit model and body clearance on its own thread (onnxruntime and the kernels
    # release the GIL); the same meshes as one after the other.
    unshifted = list(pool("fit", FIT_THREADS).map(
        lambda g: models.clear_of_body(models.explicit[g].canonical(beta)), garment_ids))
    faces = [models.catalog[g].faces for g in garment_ids]
    seconds["explicit"] = time.perf_counter() - t0
    # Where a garment was let down around an inner one and the repair still left crossings, the outfit
    # is made again with the next room below the junction (junctions.ROOMS): the usual orders, let down
    # nowhere, are made once, and so is every outfit that comes out clean.
    how = _How(untangle_layers, untangler, settings, body_field, repair, repair_settings)
    attempts: list[_Attempt] = []
    for room in junctions.ROOMS:
        t0 = time.perf_counter()
        explicit, lowered = _let_down(models, garment_ids, unshifted, room)
        seconds["explicit"] += time.perf_counter() - t0
        meshes = (unshifted, explicit, lowered)
        attempt = _layered(models, garment_ids, beta, body, meshes, faces, seconds, how)
        attempts.append(attempt)
        if attempt.faults == (0, 0) or not any(lowered):
            break
    chosen = min(attempts, key=lambda a: a.faults)  # the first of the fewest faults
    layer_ids = [BODY, *garment_ids]
    explicit, fits, fitted, fit_world, world, repairs = (
        chosen.explicit, chosen.fits, chosen.fitted, chosen.fit_world, chosen.world, chosen.repairs)
    outfit = Outfit(body, models.body.faces, list(zip(garment_ids, world, faces, strict=True)))
    report = {"garments": garment_ids, "beta": beta.tolist(), "untangled": untangle_layers}
    report["attempts"] = len(attempts)
    if untangle_layers:
        report |= _fit_report(garment_ids, explicit, faces, fits, untangler)
    if repairs:
        # What a client checks: the returned meshes cross nothing and no vertex is left inside an inner
        # layer. False only for orders the repair could not make so (a jacket tucked into pants: its
        # front hangs below the crotch; README, Outfits).
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
            drops.append(models.lowering(inner, garment, between, (unshifted[k], unshifted[j]), room))
        around.append({k for k, d in enumerate(drops) if d is not None})
        for k in range(j + 1, len(garment_ids)):  # read on this body: the bottom's crotch height
            gathering = models.raising(garment, garment_ids[k])
            drops.append(gathering and gathering.shift(explicit[j], explicit[k]))
        shift = junctions.combined([d for d in drops if d is not None])
        if shift is not None:
            explicit[j] = models.shifted_clear_of_body(explicit[j], shift)
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
    repair_settings: RepairSettings


def _layered(models, garment_ids, beta, body, meshes, faces, seconds: dict, how: _How) -> _Attempt:
    """The fit, the body map and the repair of one ``_let_down``'s explicit meshes: ``meshes`` is (the
    explicit meshes before any junction moved them, after, how far each moved). The time of each stage
    is added to ``seconds``."""
    unshifted, explicit, lowered = meshes
    untangle_layers, untangler, settings = how.untangle_layers, how.untangler, how.settings
    body_field, repair, repair_settings = how.body_field, how.repair, how.repair_settings
    layer_ids = [BODY, *garment_ids]

    def layer_fields(k, x, gradient):
        if k == 0 and body_field == "exact":
            return models.body_field(x, gradient)
        return models.fields(layer_ids[k], x, beta, gradient)

    def add(key, value):
        seconds[key] = seconds.get(key, 0.0) + value

    fitted, fits = list(explicit), []
    if untangle_layers:
        t0 = time.perf_counter()
        op = models.untangler(untangler)
        # Where a vertex is provably far from a layer, its field is not asked (fit.FAR_FIELD): pants
        # and a jacket's sleeves.
        bounds = models.far_bounds(garment_ids, unshifted, explicit)

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
    fit_world, repairs = world, []
    if untangle_layers and repair:
        t0 = time.perf_counter()
        # Every layer's fields at every fitted vertex, as the fit left them (None: evaluate again).
        cache = [r.values if r.ok else None for r in fits]
        world, repairs = untangle_world(models, layer_ids, beta, body, explicit, (fitted, cache), world,
                                        faces, repair_settings, lowered)  # fmt: skip
        add("repair", time.perf_counter() - t0)
    return _Attempt(explicit, fits, fitted, fit_world, world, repairs)


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
            return models.anchors(layer_ids[inner]).reversed_faces(v, f, body, models.body.faces)

        measured = penetration(layers, h_at, reversed_at)
        out[f"penetration_{name}"] = {k: round(v, 6) for k, v in measured.items()}
        out[f"intersections_{name}"] = intersections(layers)
    return out
