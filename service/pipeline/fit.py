"""Fit a garment mesh to its untangled field (paper 4.2, eq. 10-12; docs/design.md section 5), numpy + scipy.

For garment layer i with vertices X (initialised with the explicit model's mesh X*):

    E(X) = sum_x (f_i(x) - f*_i(X*_x))^2 + omega * E_strain(X; rest = X*)

f_i is the untangled value of layer i (``untangle`` over every layer's fields f*_k, h*_k at x). The
paper fits f_i(x) = 0; the learned field is ~1 mm off the explicit mesh, so fitting f_i = 0 would move
every vertex by that error. Subtracting each vertex's initial value f*_i(X*_x) makes only the
untangling move vertices, and a vertex where nothing is tangled stays exactly where it is.

The cost is the networks, so (docs/design.md section 5):
- values of every layer at every vertex find the vertices off their target (``conflict_tol``); only
  those and ``ring`` rings of neighbours are optimised, the rest stay fixed;
- at those vertices the fields and their x-gradients are evaluated once per outer iteration and
  linearised; L-BFGS-B runs on the linear model (untangler and strain exact) inside a box of
  +-``trust`` around the linearisation point; ``outer`` re-linearisations follow.
The gradient chains through the untangler and every layer's field gradient:
d f_i / dx = sum_k (d O_i / d f*_k) grad f*_k(x) + (d O_i / d h*_k) grad h*_k(x).

The garment's own layer comes from its explicit mesh, not its network (``own_field = "mesh"``,
``OwnField``): X* is that field's zero set by definition, so f_i at a vertex moved by d is n . d (the
signed distance to the tangent plane of X* there, n the vertex normal), exact where the learned f_i is
1-3.5 mm off its own mesh (mean over the catalog's garments); and the garment is active at each of its
own vertices (h_i = ``OWN_H``, constant): h_i says where a garment is present, and a garment is present
at its own cloth points, rims included (its learned h_i blends it out over the centimetre next to an
opening, so a hem under a jacket was only half untangled). No network runs for the own layer.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np

from service.geometry.mesh import vertex_normals
from service.geometry.rings import dilate, vertex_neighbours
from service.pipeline.fields import FieldValues
from service.pipeline.lbfgs import minimize_lbfgs
from service.pipeline.lbfgs_kernel import minimize_fit
from service.pipeline.strain import RestShape, strain_energy

# fields(layer, x (P, 3), gradient) -> FieldValues
INACTIVE = 0.1  # h of a layer made inactive: the fields' saturation value, inside the untangler's range
OWN_H = -1.0  # h of the fitted garment at its own vertices: active (the body's value)
FAR_FIELD = 0.08
"""m: a layer whose surface is known to be at least this far from a vertex (``fit_garment``'s
``bounds``) is not asked its field there: it takes no part in the untangling (``FitSettings.reach``,
3 cm), nor in the squeeze's and the repair's checks (6 cm, ``CollisionSettings.reach``). Its f there is the
bound, a lower bound on the distance, so that those stages, which ask ``|f| < t``, still look at
every vertex within t of it; its h is ``INACTIVE`` (the learned one is wrong that far from the
garment, ``far_layers``). On the latency benchmark's bodies the bounds put 59-62 % of the jacket's
vertices 8 cm or more from the pants."""
LayerFields = Callable[[int, np.ndarray, bool], FieldValues]
FullUntangler = Callable[[np.ndarray, np.ndarray, bool], tuple[np.ndarray, np.ndarray | None]]


class Untangler(Protocol):
    """``untangler(f* (P, N), h* (P, N), jacobian, row=None) -> (f (P, N), d f / d (f*, h*)
    (P, N, 2N), or only its row k (P, 1, 2N) when row=k, or None without jacobian)``.

    The fit asks for the row of the garment it fits only: the neural operator computes that row alone
    at a third of the full Jacobian's cost (``NeuralUntangler``). An optional attribute ``h_band``
    (m) says that the derivative by h*_k is exactly 0 wherever |h*_k| >= h_band: the fit then asks for
    grad h*_k only inside that band (``_linearise``)."""

    def __call__(
        self, f_star: np.ndarray, h_star: np.ndarray, jacobian: bool, row: int | None = None
    ) -> tuple[np.ndarray, np.ndarray | None]: ...


def rows_of(full: FullUntangler) -> Untangler:
    """An ``Untangler`` from an operator that only returns the whole Jacobian (``(P, N, 2N)``, as
    ``service.pipeline.untangle.untangle_with_jacobian``): the row asked for is sliced from it."""

    def untangler(f_star, h_star, jacobian, row=None):
        f, jac = full(f_star, h_star, jacobian)
        return f, (jac if jac is None or row is None else jac[:, row : row + 1])

    return untangler


@dataclass(frozen=True)
class FitSettings:
    omega: float = 1e-3
    """Weight of the strain term (eq. 10): 1 % strain on a triangle costs as much as 0.3 mm misfit."""
    conflict_tol: float = 2e-4
    """m: a vertex whose untangled field is this far from its target is optimised."""
    ring: int = 2
    """Rings of neighbours optimised with the conflicting vertices."""
    outer: int = 1
    """Linearisations of the fields (each followed by an L-BFGS run). 3 instead of 1 cost 3x the fit's
    time and left as many crossings for the repair (``benchmarks.outfits``, 3 held-out bodies: after
    the repair the same pairs, 0 in 8 of 9 outfits, the tucked T-shirt on body 1 failing either way)."""
    inner: int = 10
    """L-BFGS iterations per linearisation. 20 instead of 10 took 60 ms more for body + T-shirt + jacket
    and changed no outcome of ``benchmarks.outfits`` after the repair (mean strain 0.010 vs 0.013)."""
    trust: float = 0.01
    """m: longest Newton step a vertex starts its L-BFGS from."""
    reach: float = 0.03
    """m: a garment layer farther than this from a point takes no part in its untangling."""
    own_field: Literal["mesh", "network"] = "mesh"
    """Where the fitted garment's own fields and their gradients come from: its explicit mesh
    (``OwnField``) or its network, as for the other layers."""
    refresh: Literal["linear", "fields"] = "linear"
    """Where the values at the fitted vertices (``FitResult.values``, ``residual_after``) come from after
    the last linearisation's L-BFGS run: its linear model for the layers within reach, the networks for
    the others (``_moved_values``; the residual the L-BFGS reached), or the networks for every layer (the
    reference; with ``outer`` > 1 the next linearisations start from them). The networks asked again
    took ~12 % of the fit's time for body + 4 garments."""
    optimiser: Literal["compiled", "numpy"] = "compiled"
    """The L-BFGS run: one compiled loop that releases the GIL (``lbfgs_kernel.minimize_fit``) or the
    numpy one (``lbfgs.minimize_lbfgs``, the reference), the same iterates to rounding."""


@dataclass(frozen=True)
class OwnField:
    """The fitted garment's own fields at its vertices, from its explicit mesh ``rest (V, 3)``: f = n . (x -
    rest) with ``normals (V, 3)`` its unit vertex normals (pointing to f > 0), h ``(V,)`` constant
    (``OWN_H``; module docstring)."""

    rest: np.ndarray
    normals: np.ndarray
    h: np.ndarray

    def at(self, idx: np.ndarray, x: np.ndarray) -> FieldValues:
        """Fields of vertices ``idx (P,)`` at positions ``x (P, 3)``, with gradients."""
        n = self.normals[idx]
        return FieldValues(np.einsum("nd,nd->n", n, x - self.rest[idx]), self.h[idx], n, np.zeros_like(n))


@dataclass
class FitResult:
    vertices: np.ndarray  # (V, 3) fitted, canonical space
    optimised: np.ndarray  # (V,) bool: vertices that were ever optimised
    iterations: int  # L-BFGS iterations over all linearisations
    linearisations: int
    residual_before: float  # m, max |f_i - target| over the vertices before the fit
    residual_after: float  # m, the same after (``FitSettings.refresh``: on the linear model, or re-evaluated)
    seconds: dict[str, float] = field(default_factory=dict)  # fields / untangle / optimise
    ok: bool = True  # False when the optimiser failed; vertices then hold the best valid iterate
    rest: RestShape | None = None  # of the explicit mesh: the report's strain is measured against it
    values: tuple[np.ndarray, np.ndarray] | None = None
    """(f*, h*) ``(V, N)`` of every layer at the returned vertices, h* as the networks answer (far
    layers not made inactive; the garment's own column from ``OwnField`` when the settings say so;
    the bound and ``INACTIVE`` where ``bounds`` put a layer ``FAR_FIELD`` away), for the later
    stages to reuse; None when ``ok`` is False."""


def fit_garment(
    vertices: np.ndarray,
    faces: np.ndarray,
    layer: int,
    n_layers: int,
    fields: LayerFields,
    untangler: Untangler,
    settings: FitSettings = FitSettings(),
    bounds: np.ndarray | None = None,
) -> FitResult:
    """Fit garment ``layer`` (1..N-1; 0 is the body) with explicit mesh ``vertices (V, 3)``,
    ``faces (F, 3)``, against the fields of all ``n_layers`` layers. ``bounds (V, N)``: lower bounds
    (m) on the distance from each vertex to each layer's surface (0 where none is known): where one
    is at least ``FAR_FIELD``, that layer's field is not asked."""
    x0 = np.asarray(vertices, dtype=np.float64)
    if x0.ndim != 2 or x0.shape[1] != 3:
        raise ValueError(f"vertices must be (V, 3), got {x0.shape}")
    if not 1 <= layer < n_layers:
        raise ValueError(f"layer must be a garment layer in 1..{n_layers - 1}, got {layer}")
    faces = np.asarray(faces)
    seconds = {"fields": 0.0, "untangle": 0.0, "optimise": 0.0}
    adjacency = vertex_neighbours(faces, len(x0))
    clock = _Clock(seconds)
    own = None
    if settings.own_field == "mesh":
        own = OwnField(x0, vertex_normals(x0, faces), np.full(len(x0), OWN_H))
    everything = np.arange(len(x0))
    if bounds is not None and settings.reach >= FAR_FIELD:
        raise ValueError(f"reach {settings.reach} m: the bounds skip layers from {FAR_FIELD} m")
    with clock("fields"):
        f_star, h_raw = _values(
            fields, n_layers, x0, None if own is None else (layer, own.at(everything, x0)), bounds
        )
    h_star = np.where(far_layers(f_star, layer, settings.reach), INACTIVE, h_raw)
    if not (np.all(np.isfinite(f_star)) and np.all(np.isfinite(h_raw))):
        # A network answered NaN or inf: nothing to fit against; the explicit mesh, flagged.
        return FitResult(x0.copy(), np.zeros(len(x0), dtype=bool), 0, 0, np.nan, np.nan, seconds, False)
    with clock("untangle"):
        f_i = untangler(f_star, h_star, False)[0][:, layer]
    target = f_star[:, layer].copy()  # each vertex keeps its own field value unless untangling moves it
    residual = f_i - target
    before = float(np.abs(residual).max())
    x = x0.copy()
    optimised = np.zeros(len(x0), dtype=bool)
    iterations, linearisations, ok = 0, 0, True
    full_rest, rest, touched = RestShape.build(x0, faces), None, None
    for _ in range(settings.outer):
        conflict = np.abs(residual) > settings.conflict_tol
        if not conflict.any():
            break
        optimised |= dilate(conflict, adjacency, settings.ring)
        idx = np.flatnonzero(optimised)
        near = optimised[faces].any(axis=1)
        if touched is None or (near != touched).any():
            # Only triangles touching an optimised vertex change: the strain of the rest is constant.
            rest, touched = full_rest.subset(near), near
        with clock("fields"):
            lin = _linearise(fields, n_layers, x[idx], f_star[idx], layer, settings.reach, own, idx,
                             getattr(untangler, "h_band", None))  # fmt: skip
        if lin is None:
            ok = False  # a network answered NaN or inf: keep the last valid iterate
            break
        fl, hl, grad_f, grad_h = lin
        with clock("untangle"):
            f, jac = untangler(fl, hl, True, row=layer)
        # The untangled value is piecewise linear in (f*, h*): linearised at x[idx] with the
        # operator's Jacobian (its row of this layer) chained through every layer's field gradient (eq. 11).
        r0 = f[:, layer] - target[idx]
        g = np.einsum("nk,nkd->nd", jac[:, 0, :n_layers], grad_f)
        g += np.einsum("nk,nkd->nd", jac[:, 0, n_layers:], grad_h)
        with clock("optimise"):
            y, nit, ok = _minimise(x, idx, r0, g, rest, settings)
        iterations += nit
        linearisations += 1
        if not ok:
            break
        # After the last linearisation with refresh "linear": the values and the residual at the fitted
        # vertices from its model.
        linear = settings.refresh == "linear" and linearisations == settings.outer
        far = far_layers(f_star[idx], layer, settings.reach)  # as _linearise had them
        d = y - x[idx]
        x[idx] = y
        with clock("fields"):
            # A bound at the explicit vertex holds less how far the fit has moved it since.
            left = None if bounds is None else bounds[idx] - np.linalg.norm(y - x0[idx], axis=1)[:, None]
            known = None if own is None else (layer, own.at(idx, y))
            if linear:
                f_new, h_new = _moved_values(fields, lin, far, y, d, known, left)
            else:
                f_new, h_new = _values(fields, n_layers, y, known, left)
        if not (np.all(np.isfinite(f_new)) and np.all(np.isfinite(h_new))):
            ok = False
            break
        f_star[idx], h_raw[idx] = f_new, h_new
        h_star[idx] = np.where(far_layers(f_new, layer, settings.reach), INACTIVE, h_new)
        if linear:
            residual[idx] = r0 + np.einsum("nd,nd->n", g, d)
            break
        with clock("untangle"):
            residual[idx] = untangler(f_star[idx], h_star[idx], False)[0][:, layer] - target[idx]
    values = (f_star, h_raw) if ok else None
    after = float(np.abs(residual).max())
    return FitResult(x, optimised, iterations, linearisations, before, after, seconds, ok, full_rest, values)


def _values(fields: LayerFields, n_layers: int, x: np.ndarray, known: tuple[int, FieldValues] | None = None,
            bounds: np.ndarray | None = None):  # fmt: skip
    """f*, h* ``(P, N)`` of every layer at ``x (P, 3)``, values only; ``known`` = (layer, its values)
    is not evaluated, nor a layer where ``bounds (P, N)`` put it ``FAR_FIELD`` away or more (f* is
    then the bound, h* ``INACTIVE``)."""
    f, h = np.empty((len(x), n_layers)), np.empty((len(x), n_layers))
    for k in range(n_layers):
        if known and k == known[0]:
            f[:, k], h[:, k] = known[1].f, known[1].h
            continue
        far = np.zeros(len(x), dtype=bool) if bounds is None else bounds[:, k] >= FAR_FIELD
        if not far.any():
            v = fields(k, x, False)
            f[:, k], h[:, k] = v.f, v.h
            continue
        f[far, k], h[far, k] = bounds[far, k], INACTIVE
        ask = np.flatnonzero(~far)
        if len(ask):
            v = fields(k, x[ask], False)
            f[ask, k], h[ask, k] = v.f, v.h
    return f, h


def _linearise(fields: LayerFields, n_layers: int, x: np.ndarray, f_now: np.ndarray, layer: int, reach,
               own: OwnField | None = None, idx: np.ndarray | None = None,
               band: float | None = None):  # fmt: skip
    """Fields of every layer at ``x (P, 3)`` with x-gradients, for the linearisation: (f*, h* (P, N),
    grad f*, grad h* (P, N, 3)), or None if a network answered NaN or inf. With ``own``, layer
    ``layer``'s come from it at the vertices ``idx (P,)``.

    ``f_now (P, N)`` are the current values: a layer farther than ``reach`` from a point is inactive
    there (``far_layers``), a constant of the fit, so its gradients are 0 and are not evaluated (the
    gradient graph costs ~5 values; a jacket's sleeves are far from the pants at every vertex).

    ``band``: the untangler's derivative by h*_k is exactly 0 where |h*_k| >= band (``Untangler.h_band``;
    the neural operator sees h* only through clamp(h* / h_band), the exact one not at all: 0), so
    grad h*_k counts only inside it. Every near point gets grad f alone first (the cheaper graph, the
    same values and grad f); those its h puts inside the band then get grad h too. None: everywhere.
    """
    far = far_layers(f_now, layer, reach)
    fl, hl = f_now.copy(), np.full(f_now.shape, INACTIVE)
    grad_f, grad_h = np.zeros(f_now.shape + (3,)), np.zeros(f_now.shape + (3,))
    for k in range(n_layers):
        near = np.flatnonzero(~far[:, k])
        if not len(near):
            continue
        if own is not None and k == layer:
            v = own.at(idx, x)
        else:
            v = fields(k, x[near], True if band is None else "f")
        if not all(np.all(np.isfinite(a)) for a in v):
            return None
        fl[near, k], hl[near, k], grad_f[near, k], grad_h[near, k] = v
        if band is not None and not (own is not None and k == layer) and k > 0:
            inside = near[np.abs(hl[near, k]) < band]
            if len(inside):
                grad = fields(k, x[inside], True).grad_h
                if not np.all(np.isfinite(grad)):
                    return None
                grad_h[inside, k] = grad
    return fl, hl, grad_f, grad_h


def _moved_values(fields: LayerFields, lin, far: np.ndarray, y: np.ndarray, d: np.ndarray,
                  own: tuple[int, FieldValues] | None = None,
                  bounds: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """f*, h* ``(P, N)`` at the points ``y (P, 3)``, moved by ``d (P, 3)`` from the linearisation point of
    ``lin`` (``_linearise``'s (f*, h*, grad f*, grad h*)): of the layers within reach there, from that
    first-order model, which the fit's L-BFGS assumed (``FitSettings.refresh = "linear"``; h* keeps its
    value where ``_linearise`` did not ask grad h*, outside the untangler's band); of the layers
    ``far (P, N)`` put beyond reach (``far_layers``, as the linearisation had them), which have no gradient,
    the networks' values at y (``_values``, with the ``bounds (P, N)`` at y). Far from a garment its learned
    field is no distance: the skirt's at a long sleeve's vertices changed by up to 8 cm for a step of 2,
    and a first-order guess there changed which vertices the repair checks. ``own``: (the fitted layer,
    its exact values at y, ``OwnField``)."""
    f_lin, h_lin, grad_f, grad_h = lin
    f = f_lin + np.einsum("pkd,pd->pk", grad_f, d)
    h = h_lin + np.einsum("pkd,pd->pk", grad_h, d)
    for k in range(f.shape[1]):
        ask = np.flatnonzero(far[:, k])
        if not len(ask):
            continue
        b = None if bounds is None else bounds[ask][:, [k]]
        one = _values(lambda _, x, gradient, k=k: fields(k, x, gradient), 1, y[ask], None, b)
        f[ask, k], h[ask, k] = one[0][:, 0], one[1][:, 0]
    if own is not None:
        f[:, own[0]], h[:, own[0]] = own[1].f, own[1].h
    return f, h


def far_layers(f_star: np.ndarray, layer: int, reach: float) -> np.ndarray:
    """``(P, N)`` bool: the garment layers other than ``layer`` farther than ``reach`` from each point.

    The untangling moves a layer by millimetres; a layer centimetres away cannot be tangled with
    the one at the point. Its covariant field still says where it covers the body, and the learned
    one is wrong far from the garment (a T-shirt's h < 0 on the forearm, 33 cm from its sleeve,
    which forced a jacket's sleeve 8 mm off the arm as if a T-shirt were between them). The body
    (layer 0) always takes part: it covers everything.
    """
    far = np.abs(f_star) > reach
    far[:, 0] = False
    far[:, layer] = False
    return far


LBFGS_MEMORY = 8
LBFGS_GTOL = 1e-9
LBFGS_FIRST_STEP = 1e-4


def _minimise(x, idx, r0, g, rest, settings: FitSettings):
    """L-BFGS on the linearised misfit sum (r0 + g . d)^2 plus the exact strain term, over the
    vertices ``idx``; returns (their new positions (n, 3), iterations, finite).

    It starts from each vertex's own Newton step d = -r0 g / |g|^2 (the misfit's minimum nearest
    to it, at most ``trust`` long): the misfit is then already 0 and the iterations only trade
    it against strain, which the plain start (d = 0) reaches only after many more.
    """
    y0 = x[idx].copy()
    used, local = rest.compact(idx)
    slot = np.searchsorted(used, idx)
    xl = x[used].copy()
    gg = np.maximum(np.einsum("nd,nd->n", g, g), 1e-12)
    step = -(r0 / gg)[:, None] * g
    length = np.linalg.norm(step, axis=1, keepdims=True)
    step *= np.minimum(1.0, settings.trust / np.maximum(length, 1e-300))

    def objective(flat):
        y = flat.reshape(-1, 3)
        r = r0 + np.einsum("nd,nd->n", g, y - y0)
        xl[slot] = y
        es, gs = strain_energy(xl, local)
        e = float(r @ r) + settings.omega * es
        return e, (2 * r[:, None] * g + settings.omega * gs[slot]).reshape(-1)

    start = (y0 + step).reshape(-1)
    if settings.optimiser == "compiled":
        flat, nit, _ = minimize_fit(start, y0, r0, g, xl, slot, local.faces, local.dm_inv, settings.omega,
                                    settings.inner, LBFGS_MEMORY, LBFGS_GTOL, LBFGS_FIRST_STEP)  # fmt: skip
        y = flat.reshape(-1, 3)
        ok = bool(np.all(np.isfinite(y)))
        return (y if ok else y0), nit, ok
    res = minimize_lbfgs(objective, start, settings.inner, LBFGS_MEMORY, LBFGS_GTOL, LBFGS_FIRST_STEP)
    y = res.x.reshape(-1, 3)
    ok = bool(np.all(np.isfinite(y)))
    return (y if ok else y0), res.nit, ok


class _Clock:
    """``with clock("stage"):`` adds the block's wall time to ``seconds["stage"]``."""

    def __init__(self, seconds: dict[str, float]):
        self.seconds = seconds

    def __call__(self, stage: str):
        self.stage = stage
        return self

    def __enter__(self):
        self.t0 = time.perf_counter()

    def __exit__(self, *exc):
        self.seconds[self.stage] += time.perf_counter() - self.t0
