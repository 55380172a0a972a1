"""The untangling operator O(f*, h*) (paper 3.2, eq. 6; docs/design.md section 4): exact reference.

Per query point, layers k = 0..N-1 are ordered inner to outer and layer 0 is the body. Inputs are the
signed distances f*_k (metres, negative on the body side of layer k) and covariant fields h*_k; layer k
is active where h*_k < 0, and the body is always active (its h* is ignored). For consecutive active
layers a < b the outer one must lie at least ``delta`` outside the inner one::

    f_a - f_b >= delta

and ``untangle`` returns the weighted least-squares projection onto these constraints,
``argmin sum_k w_k (f_k - f*_k)^2``; inactive layers are returned unchanged. With
g_k = f_k + r_k delta (r_k the rank of k among the active layers) this is weighted isotonic regression,
g non-increasing over the active layers, solved exactly by pool-adjacent-violators (PAV): a loop over
the few layers, vectorised across points. ``untangle_minmax`` solves the same problem by the min-max
formula of isotonic regression and is the reference the PAV is tested against. An infinite weight
(the body's, by default) fixes that layer: a pool containing it takes its value.

The projection is continuous (1-Lipschitz in the w-weighted norm) and piecewise linear in f*; it is
discontinuous in h* only where a layer switches between active and inactive.

``untangle_sign_only`` is the literal eq. 6 (a constraint only on the signs of f), kept as a documented
baseline and NOT used: its closest feasible point moves a field to exactly 0 over a whole slab, so a
tangled vertex sits where its untangled field is 0 with zero gradient and a fit never moves it
(``tests/pipeline/test_untangle.py`` shows it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

GAP_DELTA = 0.004
"""Default gap (m) between consecutive active layers."""


def default_weights(n_layers: int) -> np.ndarray:
    """Weights ``(N,)`` float64: the body (layer 0) infinite, i.e. fixed, every garment 1."""
    w = np.ones(n_layers)
    w[0] = np.inf
    return w


def _check(f_star, h_star, weights) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    f_star = np.asarray(f_star, dtype=np.float64)
    h_star = np.asarray(h_star, dtype=np.float64)
    if f_star.ndim != 2 or f_star.shape[1] < 1:
        raise ValueError(f"f_star must be (B, N) with N >= 1, got {f_star.shape}")
    if h_star.shape != f_star.shape:
        raise ValueError(f"h_star must have the shape of f_star {f_star.shape}, got {h_star.shape}")
    if not (np.isfinite(f_star).all() and np.isfinite(h_star).all()):
        raise ValueError("f_star and h_star must be finite")
    n = f_star.shape[1]
    w = default_weights(n) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (n,):
        raise ValueError(f"weights must be ({n},), got {w.shape}")
    if not np.all(w > 0) or not np.all(np.isfinite(w[1:])):
        raise ValueError("weights must be > 0, and finite except the body's (weights[0] may be inf)")
    return f_star, h_star, w


def active_layers(h_star: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(active ``(B, N) bool``, rank among the active layers ``(B, N) int``) for ``h_star (B, N)``.

    The body (layer 0) is always active; the rank of an inactive layer is meaningless.
    """
    active = np.asarray(h_star) < 0
    active[:, 0] = True
    return active, np.cumsum(active, axis=1) - 1


def _pooled(va, wa, vb, wb) -> np.ndarray:
    """Weighted mean of two pools ``(P,)``; a pool of infinite weight keeps its value."""
    finite = np.isfinite(wa) & np.isfinite(wb)
    wa_, wb_ = np.where(finite, wa, 1.0), np.where(finite, wb, 1.0)
    mean = (wa_ * va + wb_ * vb) / (wa_ + wb_)
    return np.where(np.isinf(wa), va, np.where(np.isinf(wb), vb, mean))


@dataclass
class Pools:
    """PAV result for ``B`` points of ``N`` layers.

    active, rank: ``(B, N)`` as in ``active_layers``.
    pool: ``(B, N) int`` index of each active layer's pool (0 = innermost); -1 for inactive layers.
    value, weight: ``(B, N)`` g value and total weight of each pool (entries past the last pool unused).
    """

    active: np.ndarray
    rank: np.ndarray
    pool: np.ndarray
    value: np.ndarray
    weight: np.ndarray


def pav_pools(f_star: np.ndarray, h_star: np.ndarray, weights: np.ndarray, delta: float) -> Pools:
    """Pool-adjacent-violators on g = f* + r delta (non-increasing), for checked inputs ``(B, N)``."""
    B, N = f_star.shape
    active, rank = active_layers(h_star)
    g = f_star + rank * delta
    value, weight = np.zeros((B, N)), np.zeros((B, N))
    start = np.zeros((B, N), dtype=np.int64)  # rank of each pool's first layer
    top = np.full(B, -1)
    for k in range(N):
        p = np.flatnonzero(active[:, k])
        t = top[p] + 1
        value[p, t], weight[p, t], start[p, t] = g[p, k], weights[k], rank[p, k]
        top[p] = t
        while p.size:  # merge the top two pools while they violate g non-increasing
            p = p[top[p] >= 1]
            t = top[p]
            violated = value[p, t - 1] < value[p, t]
            p, t = p[violated], t[violated]
            value[p, t - 1] = _pooled(value[p, t - 1], weight[p, t - 1], value[p, t], weight[p, t])
            weight[p, t - 1] += weight[p, t]
            top[p] = t - 1
    exists = np.arange(N)[None, :] <= top[:, None]  # (B, pools)
    pool = ((start[:, None, :] <= rank[:, :, None]) & exists[:, None, :]).sum(axis=2) - 1
    return Pools(active, rank, np.where(active, pool, -1), value, weight)


def untangle(f_star, h_star, weights=None, delta: float = GAP_DELTA) -> np.ndarray:
    """Untangled fields ``f (B, N)`` float64 (exact, by PAV).

    f_star: ``(B, N)`` signed distances (m) of layers inner to outer, layer 0 the body.
    h_star: ``(B, N)`` covariant fields; layer k active where h*_k < 0 (the body always).
    weights: ``(N,)`` positive, ``weights[0]`` may be inf; default ``default_weights(N)``.
    delta: gap (m) between consecutive active layers.
    """
    f_star, h_star, w = _check(f_star, h_star, weights)
    pools = pav_pools(f_star, h_star, w, delta)
    rows = np.arange(len(f_star))[:, None]
    g = pools.value[rows, np.maximum(pools.pool, 0)]
    return np.where(pools.active, g - pools.rank * delta, f_star)


def untangle_jacobian(f_star, h_star, weights=None, delta: float = GAP_DELTA) -> np.ndarray:
    """Jacobian ``(B, N, N)`` of ``untangle`` w.r.t. f*, ``J[b, k, j] = d f_k / d f*_j`` (exact).

    Piecewise constant: within a pool P, ``d f_k / d f*_j = w_j / sum_P w`` (1 for the body and 0 for
    the others if P contains the body); inactive layers have a unit row. Arguments as ``untangle``.
    At a kink (adjacent pools with equal values, which PAV keeps apart) it is the Jacobian of that
    finer pooling: a limit of Jacobians at nearby points, not necessarily a one-sided derivative.
    """
    f_star, h_star, w = _check(f_star, h_star, weights)
    pools = pav_pools(f_star, h_star, w, delta)
    rows = np.arange(len(f_star))[:, None]
    total = pools.weight[rows, np.maximum(pools.pool, 0)]  # (B, N) weight of each layer's pool
    same = (pools.pool[:, :, None] == pools.pool[:, None, :]) & pools.active[:, :, None]
    same &= pools.active[:, None, :]
    fixed = np.isinf(total)[:, :, None]  # the pool holds an infinite weight: it takes that value
    share = np.where(np.isinf(w), 1.0, w)[None, None, :] / np.where(fixed, 1.0, total[:, :, None])
    share = np.where(fixed, np.isinf(w)[None, None, :], share)
    jac = np.where(same, share, 0.0)
    inactive = ~pools.active
    jac[inactive, np.nonzero(inactive)[1]] = 1.0
    return jac


def untangle_with_jacobian(f_star, h_star, jacobian: bool = True, delta: float = GAP_DELTA):
    """``untangle`` with default weights as the fit calls an operator: (f ``(B, N)``, Jacobian
    ``(B, N, 2N)`` w.r.t. (f*, h*) or None). The h* columns are 0: the exact operator is piecewise
    constant in h*."""
    f = untangle(f_star, h_star, delta=delta)
    if not jacobian:
        return f, None
    jac = np.zeros((*f.shape, 2 * f.shape[1]))
    jac[:, :, : f.shape[1]] = untangle_jacobian(f_star, h_star, delta=delta)
    return f, jac


def settled(f_star: np.ndarray, h_star: np.ndarray, delta: float, band: float, slack: float) -> np.ndarray:
    """``(B,) bool``: points whose untangled fields are f* for every active set an operator blending
    layers in over ``|h*| < band`` can see: the layers with h* < band (and the body), taken as active,
    already lie ``delta + slack`` apart, consecutive pair by consecutive pair. Then so does any subset
    of them (gaps add up), so the projection (``untangle``) is the identity there, and a learned operator
    is trusted only ``slack`` away from its kinks. ``f_star``, ``h_star`` ``(B, N)``, layer 0 the body."""
    f_star, h_star = np.asarray(f_star), np.asarray(h_star)
    ok = np.ones(len(f_star), dtype=bool)
    inner = f_star[:, 0].copy()  # f* of the last possibly active layer so far
    for k in range(1, f_star.shape[1]):
        maybe = h_star[:, k] < band
        ok &= ~maybe | (inner - f_star[:, k] >= delta + slack)
        inner = np.where(maybe, f_star[:, k], inner)
    return ok


def untangle_minmax(f_star, h_star, weights=None, delta: float = GAP_DELTA) -> np.ndarray:
    """Untangled fields ``(B, N)`` by the min-max formula; the reference for ``untangle``.

    For non-increasing isotonic regression ``g_k = min_{i <= k} max_{j >= k} M(i, j)`` with M(i, j) the
    weighted mean of g* over the active layers i..j (the mean of the infinite-weight ones if any).
    Inactive layers get weight 0, which leaves the formula unchanged for the active ones. Arguments
    as ``untangle``; O(N^2) memory per point.
    """
    f_star, h_star, w = _check(f_star, h_star, weights)
    active, rank = active_layers(h_star)
    g = f_star + rank * delta
    fixed = active & np.isinf(w)[None, :]
    wf = np.where(active & ~fixed, np.where(np.isinf(w), 0.0, w)[None, :], 0.0)

    def interval_sums(x):  # (B, N) -> (B, i, j) sum of x[i..j]
        c = np.concatenate([np.zeros((len(x), 1)), np.cumsum(x, axis=1)], axis=1)
        return c[:, None, 1:] - c[:, :-1, None]

    W, S = interval_sums(wf), interval_sums(wf * g)
    C, SC = interval_sums(fixed.astype(np.float64)), interval_sums(np.where(fixed, g, 0.0))
    n = f_star.shape[1]
    upper = np.arange(n)[:, None] <= np.arange(n)[None, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(C > 0, SC / C, S / W)
    mean = np.where(upper & ((W > 0) | (C > 0)), mean, -np.inf)
    max_right = np.flip(np.maximum.accumulate(np.flip(mean, axis=2), axis=2), axis=2)  # [b, i, k]
    g_out = np.where(upper, max_right, np.inf).min(axis=1)
    return np.where(active, g_out - rank * delta, f_star)


def untangle_sign_only(f_star, h_star, weights=None) -> np.ndarray:
    """Literal eq. 6, a baseline only: closest point ``(B, N)`` with no active pair i < j having
    f_i < 0 and f_j > 0 (a point inside an inner layer and outside an outer one).

    Feasible sign patterns over the active layers are "f >= 0 up to some rank m, f <= 0 from it", so
    the projection clamps the violating fields to exactly 0 for the cheapest m (first on ties). No
    gap, and the clamped field is flat (zero gradient) wherever it applies. Arguments as ``untangle``.
    """
    f_star, h_star, w = _check(f_star, h_star, weights)
    active, rank = active_layers(h_star)
    best_cost, best_f = np.full(len(f_star), np.inf), f_star.copy()
    for m in range(f_star.shape[1] + 1):
        target = np.where(rank < m, np.maximum(f_star, 0.0), np.minimum(f_star, 0.0))
        target = np.where(active, target, f_star)
        move = target - f_star
        cost = np.where(np.isinf(w), np.inf, np.where(np.isinf(w), 1.0, w) * move**2)
        cost = np.where(move != 0, cost, 0.0).sum(axis=1)
        better = cost < best_cost
        best_cost[better], best_f[better] = cost[better], target[better]
    return best_f
