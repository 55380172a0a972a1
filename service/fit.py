"""Fit a garment mesh to its untangled field (paper 4.2, eq. 10-12; DESIGN.md section 5), numpy + scipy.

For garment layer i with vertices X (initialised with the explicit model's mesh X*):

    E(X) = sum_x (f_i(x) - f*_i(X*_x))^2 + omega * E_strain(X; rest = X*)

f_i is the untangled value of layer i (``untangle`` over every layer's fields f*_k, h*_k at x). The
paper fits f_i(x) = 0; the learned field is ~1 mm off the explicit mesh, so fitting f_i = 0 would move
every vertex by that error. Subtracting each vertex's initial value f*_i(X*_x) makes only the
untangling move vertices, and a vertex where nothing is tangled stays exactly where it is.

The cost is the networks, so (DESIGN.md section 5):
- values of every layer at every vertex find the vertices off their target (``conflict_tol``); only
  those and ``ring`` rings of neighbours are optimised, the rest stay fixed;
- at those vertices the fields and their x-gradients are evaluated once per outer iteration and
  linearised; L-BFGS-B runs on the linear model (untangler and strain exact) inside a box of
  +-``trust`` around the linearisation point; ``outer`` re-linearisations follow.
The gradient chains through the untangler and every layer's field gradient:
d f_i / dx = sum_k (d O_i / d f*_k) grad f*_k(x) + (d O_i / d h*_k) grad h*_k(x).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize

from service.fields import FieldValues
from service.strain import RestShape, strain_energy

# fields(layer, x (P, 3), gradient) -> FieldValues
# untangler(f* (P, N), h* (P, N), jacobian) -> (f (P, N), d f / d (f*, h*) (P, N, 2N) or None)
LayerFields = Callable[[int, np.ndarray, bool], FieldValues]
Untangler = Callable[[np.ndarray, np.ndarray, bool], tuple[np.ndarray, np.ndarray | None]]


@dataclass(frozen=True)
class FitSettings:
    omega: float = 1e-3
    """Weight of the strain term (eq. 10): 1 % strain on a triangle costs as much as 0.3 mm misfit."""
    conflict_tol: float = 2e-4
    """m: a vertex whose untangled field is this far from its target is optimised."""
    ring: int = 2
    """Rings of neighbours optimised with the conflicting vertices."""
    outer: int = 4
    """Linearisations of the fields (each followed by an L-BFGS run)."""
    inner: int = 80
    """L-BFGS-B iterations per linearisation."""
    trust: float = 0.01
    """m: box around the linearisation point each coordinate stays in."""


@dataclass
class FitResult:
    vertices: np.ndarray  # (V, 3) fitted, canonical space
    optimised: np.ndarray  # (V,) bool: vertices that were ever optimised
    iterations: int  # L-BFGS iterations over all linearisations
    linearisations: int
    residual_before: float  # m, max |f_i - target| over the vertices before the fit
    residual_after: float  # m, the same after (fields re-evaluated)
    seconds: dict[str, float] = field(default_factory=dict)  # fields / untangle / optimise
    ok: bool = True  # False when the optimiser failed; vertices then hold the best valid iterate


def vertex_neighbours(faces: np.ndarray, n_vertices: int):
    """Sparse vertex adjacency ``(V, V)`` of ``faces (F, 3)``."""
    from scipy.sparse import coo_matrix

    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.concatenate([e, e[:, ::-1]])
    return coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_vertices, n_vertices)).tocsr()


def dilate(mask: np.ndarray, adjacency, rings: int) -> np.ndarray:
    out = mask.copy()
    for _ in range(rings):
        out = out | (adjacency @ out.astype(np.float64) > 0)
    return out


def _untangled_layer(fields: LayerFields, untangler: Untangler, layer: int, n_layers: int, x: np.ndarray):
    """(untangled f of ``layer`` (P,), f* (P, N), h* (P, N)) at ``x (P, 3)``, values only."""
    vals = [fields(k, x, False) for k in range(n_layers)]
    f_star = np.stack([v.f for v in vals], 1)
    h_star = np.stack([v.h for v in vals], 1)
    f, _ = untangler(f_star, h_star, False)
    return f[:, layer], f_star, h_star


def fit_garment(
    vertices: np.ndarray,
    faces: np.ndarray,
    layer: int,
    n_layers: int,
    fields: LayerFields,
    untangler: Untangler,
    settings: FitSettings = FitSettings(),
) -> FitResult:
    """Fit garment ``layer`` (1..N-1; 0 is the body) with explicit mesh ``vertices (V, 3)``,
    ``faces (F, 3)``, against the fields of all ``n_layers`` layers."""
    x0 = np.asarray(vertices, dtype=np.float64)
    if x0.ndim != 2 or x0.shape[1] != 3:
        raise ValueError(f"vertices must be (V, 3), got {x0.shape}")
    if not 1 <= layer < n_layers:
        raise ValueError(f"layer must be a garment layer in 1..{n_layers - 1}, got {layer}")
    seconds = {"fields": 0.0, "untangle": 0.0, "optimise": 0.0}
    rest = RestShape.build(x0, faces)
    adjacency = vertex_neighbours(np.asarray(faces), len(x0))
    t0 = time.perf_counter()
    f_i, f_star, _ = _untangled_layer(fields, untangler, layer, n_layers, x0)
    seconds["fields"] += time.perf_counter() - t0
    target = f_star[:, layer]  # each vertex keeps its own field value unless untangling moves it
    residual = f_i - target
    before = float(np.abs(residual).max())
    x = x0.copy()
    optimised = np.zeros(len(x0), dtype=bool)
    iterations, linearisations, ok = 0, 0, True
    for _ in range(settings.outer):
        conflict = np.abs(residual) > settings.conflict_tol
        if not conflict.any():
            break
        active = dilate(conflict, adjacency, settings.ring)
        optimised |= active
        idx = np.flatnonzero(active)
        t0 = time.perf_counter()
        lin = [fields(k, x[idx], True) for k in range(n_layers)]
        seconds["fields"] += time.perf_counter() - t0
        y0 = x[idx].copy()
        # Only triangles touching an optimised vertex change: the strain of the rest is constant.
        near = rest.subset(active[faces].any(axis=1))
        a = np.stack([v.f for v in lin], 1)  # (n, N)
        ga = np.stack([v.grad_f for v in lin], 1)  # (n, N, 3)
        b = np.stack([v.h for v in lin], 1)
        gb = np.stack([v.grad_h for v in lin], 1)
        t_idx = target[idx]
        timing = {"untangle": 0.0}

        def objective(flat, idx=idx, y0=y0, a=a, ga=ga, b=b, gb=gb, t_idx=t_idx, timing=timing, near=near):
            y = flat.reshape(-1, 3)
            d = y - y0
            fs = a + np.einsum("nkd,nd->nk", ga, d)
            hs = b + np.einsum("nkd,nd->nk", gb, d)
            t1 = time.perf_counter()
            f, jac = untangler(fs, hs, True)
            timing["untangle"] += time.perf_counter() - t1
            r = f[:, layer] - t_idx
            dfdx = np.einsum("nk,nkd->nd", jac[:, layer, :n_layers], ga)
            dfdx += np.einsum("nk,nkd->nd", jac[:, layer, n_layers:], gb)
            xf = x.copy()
            xf[idx] = y
            es, gs = strain_energy(xf, near)
            e = float(r @ r) + settings.omega * es
            g = 2 * r[:, None] * dfdx + settings.omega * gs[idx]
            # In mm^2: L-BFGS-B's absolute gradient tolerance would otherwise stop at microns.
            return 1e6 * e, 1e6 * g.reshape(-1)

        bounds = np.stack([(y0 - settings.trust).reshape(-1), (y0 + settings.trust).reshape(-1)], 1)
        t0 = time.perf_counter()
        res = minimize(
            objective, y0.reshape(-1), jac=True, method="L-BFGS-B", bounds=bounds,
            options={"maxiter": settings.inner, "maxcor": 10},
        )  # fmt: skip
        seconds["optimise"] += time.perf_counter() - t0 - timing["untangle"]
        seconds["untangle"] += timing["untangle"]
        iterations += int(res.nit)
        linearisations += 1
        y = res.x.reshape(-1, 3)
        if not np.all(np.isfinite(y)):
            ok = False
            break
        x[idx] = y
        t0 = time.perf_counter()
        f_i, _, _ = _untangled_layer(fields, untangler, layer, n_layers, x)
        seconds["fields"] += time.perf_counter() - t0
        residual = f_i - target
    return FitResult(
        x, optimised, iterations, linearisations, before, float(np.abs(residual).max()), seconds, ok
    )
