"""What collision handling keeps per garment and per ordered pair of garments, made on first use.

Per garment: its drape on the mean body (the explicit model at the default shape) and that drape's
slices, and where its vertices sit on the body. Per ordered pair: the junctions (a let-down or a
gathering, ``collisions.junctions``) and how far each vertex of one drape is from the other. None of
it depends on the request's body, so a server makes each once (``warm`` makes the bundled ones up
front) and every request reads it. Thread-safe: two requests may ask for the same pair at once.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from service.geometry.anchors import BodyAnchors
from service.geometry.closest import ClosestPoint
from service.pipeline.body import DEFAULT_BETA
from service.pipeline.canonical import CanonicalSpace
from service.pipeline.catalog import Garment
from service.pipeline.collisions import junctions
from service.pipeline.collisions.clearance import BodyClearance
from service.pipeline.collisions.layering import GarmentProfile, LayeringRule, Refusal
from service.pipeline.collisions.settings import SETTINGS, CollisionSettings
from service.pipeline.collisions.traits import traits_of, tucked


@dataclass(frozen=True)
class Drape:
    """A garment's drape on the mean body: canonical vertices ``(V, 3)``, cleared of the body, and the
    profile of its slices (``collisions.layering.GarmentProfile``)."""

    vertices: np.ndarray
    profile: GarmentProfile


@dataclass(frozen=True)
class Junction:
    """An ordered pair's junction: the inner garment's gathering (a top tucked into a bottom whose
    crotch is above its hem) or the outer garment's let-down ``(V_outer, 3)`` on the mean body; at
    most one of them, both None where the pair has no junction run."""

    raising: junctions.Gathering | None
    lowering: np.ndarray | None


class PairCaches:
    """Per-garment and per-pair geometry of a catalog, made on first use and kept."""

    def __init__(self, catalog: dict[str, Garment], explicit: dict, space: CanonicalSpace,
                 clearance: BodyClearance, settings: CollisionSettings = SETTINGS):  # fmt: skip
        self.catalog = catalog
        self.explicit = explicit
        self.space = space
        self.clearance = clearance
        self.settings = settings
        self._layering: LayeringRule | None = None
        self._anchors: dict[str, BodyAnchors] = {}
        self._junctions: dict[tuple[str, str], Junction] = {}
        self._drapes: dict[str, Drape] = {}
        self._gaps: dict[tuple[str, str], np.ndarray] = {}
        self._lock = threading.Lock()

    def layering_rule(self) -> LayeringRule:
        """Which orders cloth can take (``collisions.layering``), over the mean body."""
        if self._layering is None:
            self._layering = LayeringRule(self.space.mean_vertices, self.space.faces)
        return self._layering

    def refusals(self, garment_ids: list[str]) -> list[Refusal]:
        """Why cloth cannot take the order ``garment_ids`` (inner to outer): empty when it can."""
        return self.layering_rule().refusals([self.catalog[g] for g in garment_ids])

    def anchors(self, garment_id: str) -> BodyAnchors:
        """Where the garment's vertices sit on the body (``service.geometry.anchors``), made once."""
        if garment_id not in self._anchors:
            garment = self.catalog[garment_id]
            self._anchors[garment_id] = BodyAnchors.build(garment.vertices, self.space.closest)
        return self._anchors[garment_id]

    def lowering(self, inner_id: str, outer_id: str, between: int = 0,
                 on: tuple[np.ndarray, np.ndarray] | None = None,
                 extra: float | None = None) -> np.ndarray | None:  # fmt: skip
        """The canonical displacement (V, 3) that lets ``outer_id``'s junctions down below
        ``inner_id``'s (``collisions.junctions``), or None where their drapes on the mean body have no
        junction run. ``between``: garments between the two let down around ``inner_id`` too.
        ``on``: the two garments' explicit meshes on the body they are worn on (canonical, before any
        junction moved them): the drop is then that body's (``junctions.body_run``, 25-45 ms a pair in
        a one-off timing), as every request asks; else the mean body's, made on first use (~1 ms).
        ``extra``: the room below the inner junction (default the first of ``settings.rooms``)."""
        extra = self.settings.extra if extra is None else extra
        if self._junction(inner_id, outer_id).lowering is None:
            return None
        if on is None and between == 0 and extra == self.settings.extra:
            return self._junction(inner_id, outer_id).lowering
        with self._lock:  # made by _junction
            inner, outer = (self._drape(g) for g in (inner_id, outer_id))
        body, length = self.layering_rule().body, None
        if on is not None:
            faces = (self.catalog[inner_id].faces, self.catalog[outer_id].faces)
            length = junctions.body_run(inner.profile, outer.profile, body, on[0], faces[0], on[1], faces[1])
        return junctions.lowering(inner.profile, outer.profile, body, outer.vertices, between, length, extra)

    def raising(self, inner_id: str, outer_id: str) -> junctions.Gathering | None:
        """How a top tucked into ``outer_id`` is gathered up above its crotch (``junctions.raising``), or
        None; made and kept as ``lowering``. A top in a bottom is raised, never the bottom let down."""
        return self._junction(inner_id, outer_id).raising

    def _junction(self, inner_id: str, outer_id: str) -> Junction:
        """The junction of an ordered pair, kept."""
        key = (inner_id, outer_id)
        with self._lock:  # two requests' threads may ask for the same pair at once
            if key not in self._junctions:
                inner, outer = (self._drape(g) for g in key)
                rule = self.layering_rule()
                body = rule.body
                a, b = self.catalog[inner_id], self.catalog[outer_id]
                up = None
                if tucked(traits_of(rule, a), traits_of(rule, b)):  # a top in a bottom
                    up = junctions.raising(inner.profile, outer.profile, body, inner.vertices, a.faces,
                                           outer.vertices)  # fmt: skip
                down = None if up is not None else junctions.lowering(inner.profile, outer.profile, body,
                                                                        outer.vertices)  # fmt: skip
                self._junctions[key] = Junction(up, down)
            return self._junctions[key]

    def gap(self, garment_id: str, other_id: str) -> np.ndarray:
        """``(V,)`` m: how far each vertex of ``garment_id``'s drape on the mean body is from
        ``other_id``'s drape there, in canonical space, rounded down to ``settings.gap_step``: made on
        first use (~20 ms) and kept in a byte a vertex (an imported catalog of 50 garments: 2,450
        ordered pairs, 25 MB)."""
        key = (garment_id, other_id)
        step = self.settings.gap_step
        with self._lock:
            if key not in self._gaps:
                x, y = self._drape(garment_id).vertices, self._drape(other_id).vertices
                d = ClosestPoint.build(y, self.catalog[other_id].faces).query(x).distance
                self._gaps[key] = np.minimum(np.floor(d / step), 255).astype(np.uint8)
            return self._gaps[key] * step

    def far_bounds(self, garment_ids: list[str], unshifted: list[np.ndarray], explicit: list[np.ndarray]):
        """Per garment, ``(V, N)`` lower bounds (m) on the distance from each of its explicit vertices
        ``explicit[i]`` to each layer's surface on this body (``fit_garment``'s ``bounds``; 0 for the
        body and the garment itself). ``unshifted``: the explicit meshes before the junctions moved
        them, as the fields know them. A vertex is as far from the other garment's mean drape as
        ``gap`` says, less how far it is from its own mean drape, less how far the other garment's
        mesh is, at most, from its mean drape (the distance to a mesh changes no faster than the
        point or the mesh moves)."""
        with self._lock:
            drapes = [self._drape(g).vertices for g in garment_ids]
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
        garment's drape (~60 ms a garment) and every ordered pair of bundled garments' ``gap``
        (~12 ms a pair); a pair's lowering is then ~1 ms, made when asked."""
        self.layering_rule().warm(self.catalog.values())
        with self._lock:
            for garment_id in self.catalog:
                self._drape(garment_id)
        # The bundled garments' pairs (42, 0.5 s); an imported garment's are made on first use, so
        # that start-up does not grow with the square of the catalog.
        bundled = [g for g, garment in self.catalog.items() if garment.origin == "bundled"]
        for g in bundled:
            for other in bundled:
                if g != other:
                    self.gap(g, other)

    def _drape(self, garment_id: str) -> Drape:
        """The garment's drape on the mean body and its slices' profile, kept (the caller holds the lock)."""
        if garment_id not in self._drapes:
            beta = np.asarray(DEFAULT_BETA, dtype=np.float64)
            drape = self.clearance.clear_of_body(self.explicit[garment_id].canonical(beta))
            body = self.layering_rule().body
            profile = GarmentProfile.build(garment_id, drape, self.catalog[garment_id].faces, body)
            self._drapes[garment_id] = Drape(drape, profile)
        return self._drapes[garment_id]
