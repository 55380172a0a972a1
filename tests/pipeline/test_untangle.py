"""Tests of ``service/pipeline/untangle.py`` (exact operator, eq. 6 baseline) and
``service/pipeline/untangle_onnx.py`` (the committed neural operator, ``models/untangler``; refresh it with
``python -m training.untangler``).

Tolerances: the exact operator is checked to 1e-9 m (constraints) and 1e-12 m (PAV vs min-max); the
QP solver to 1e-7 m. The neural operator is checked against its stored evaluation and the 0.5 mm
target (``ERROR_BOUND_MM``).
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy.optimize import minimize

from service.pipeline.untangle import (
    GAP_DELTA,
    active_layers,
    default_weights,
    settled,
    untangle,
    untangle_jacobian,
    untangle_minmax,
    untangle_sign_only,
)
from service.pipeline.untangle_onnx import (
    ERROR_BOUND_MM,
    EXPORT_TOLERANCE,
    N_SLOTS,
    NEAR_SURFACE,
    PAD_F,
    PAD_H,
    SETTLED_SLACK,
    NeuralUntangler,
)
from training.untangler_data import SAMPLERS, sample_layered


def random_fields(seed: int, n: int, n_layers: int) -> tuple[np.ndarray, np.ndarray]:
    """``(3 n, N)`` f*, h*: the paper's range, values on a 2 mm grid (ties, exact gaps), and near 0."""
    rng = np.random.default_rng(seed)
    f = np.concatenate(
        [
            rng.uniform(-0.2, 1.5, (n, n_layers)),
            0.002 * rng.integers(-5, 6, (n, n_layers)),
            rng.normal(0.0, 0.01, (n, n_layers)),
        ]
    )
    return f, rng.uniform(-1.0, 1.0, f.shape)


def random_weights(seed: int, n_layers: int, body_fixed: bool = True) -> np.ndarray:
    w = np.random.default_rng(seed).uniform(0.5, 3.0, n_layers)
    if body_fixed:
        w[0] = np.inf
    return w


def consecutive_gaps(f: np.ndarray, h: np.ndarray) -> np.ndarray:
    """f_a - f_b over all consecutive active pairs a < b of all rows (1-D)."""
    active, _ = active_layers(h)
    last = np.zeros(len(f), dtype=np.int64)  # the body is always active
    gaps = []
    for k in range(1, f.shape[1]):
        rows = np.flatnonzero(active[:, k])
        gaps.append(f[rows, last[rows]] - f[rows, k])
        last[rows] = k
    return np.concatenate(gaps) if gaps else np.zeros(0)


def weighted_norm(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """sqrt(sum_k w_k x_k^2) per row, for rows whose infinite-weight entries are 0."""
    return np.sqrt((np.where(np.isinf(w), 0.0, w) * x**2).sum(axis=1))


# ---------------------------------------------------------------- exact operator


@pytest.mark.parametrize("n_layers", [1, 2, 3, 5, 7])
@pytest.mark.parametrize("delta", [GAP_DELTA, 0.0, 0.02])
def test_every_constraint_holds(n_layers, delta):
    f_star, h_star = random_fields(n_layers, 2000, n_layers)
    f = untangle(f_star, h_star, random_weights(1, n_layers), delta)
    assert np.all(consecutive_gaps(f, h_star) >= delta - 1e-9)


@pytest.mark.parametrize("n_layers", [1, 2, 3, 5, 7])
@pytest.mark.parametrize("body_fixed", [True, False])
def test_pav_matches_minmax_reference(n_layers, body_fixed):
    f_star, h_star = random_fields(10 + n_layers, 2000, n_layers)
    w = random_weights(n_layers, n_layers, body_fixed)
    np.testing.assert_allclose(
        untangle(f_star, h_star, w), untangle_minmax(f_star, h_star, w), rtol=0, atol=1e-12
    )


def qp_reference(f_star: np.ndarray, h_star: np.ndarray, w: np.ndarray, delta: float) -> np.ndarray:
    """One point ``(N,)`` by SLSQP on the garments' active values, the body fixed."""
    active, _ = active_layers(h_star[None])
    order = np.flatnonzero(active[0])
    free = order[1:]
    # constraints f_a - f_b >= delta for consecutive active a < b, as A x >= b over the free values
    A, b = np.zeros((len(order) - 1, len(free))), np.full(len(order) - 1, delta)
    for row, (a, _b) in enumerate(zip(order[:-1], order[1:], strict=True)):
        if a == 0:
            b[row] -= f_star[0]
        else:
            A[row, row - 1] = 1.0
        A[row, row] = -1.0
    result = minimize(
        lambda x: (w[free] * (x - f_star[free]) ** 2).sum(),
        f_star[free],
        jac=lambda x: 2 * w[free] * (x - f_star[free]),
        constraints=[{"type": "ineq", "fun": lambda x: A @ x - b, "jac": lambda x: A}],
        method="SLSQP",
        options={"ftol": 1e-12, "maxiter": 1000},
    )
    assert result.success, result.message
    f = f_star.copy()
    f[free] = result.x
    return f


def test_optimal_against_qp_solver():
    f_star, h_star = random_fields(20, 20, 5)
    w = random_weights(2, 5)
    f = untangle(f_star, h_star, w)
    for i in range(len(f_star)):
        qp = qp_reference(f_star[i], h_star[i], w, GAP_DELTA)
        assert np.all(consecutive_gaps(qp[None], h_star[i : i + 1]) >= GAP_DELTA - 1e-9)
        np.testing.assert_allclose(f[i], qp, rtol=0, atol=1e-7)
        ours, theirs = ((np.where(np.isinf(w), 0, w) * (x - f_star[i]) ** 2).sum() for x in (f[i], qp))
        assert ours <= theirs + 1e-12


def test_idempotent():
    f_star, h_star = random_fields(30, 2000, 5)
    f = untangle(f_star, h_star)
    np.testing.assert_allclose(untangle(f, h_star), f, rtol=0, atol=1e-12)


def test_inactive_layers_and_body_untouched():
    f_star, h_star = random_fields(40, 2000, 5)
    f = untangle(f_star, h_star, random_weights(3, 5))
    active, _ = active_layers(h_star)
    assert np.array_equal(f[~active], f_star[~active])
    assert np.array_equal(f[:, 0], f_star[:, 0])
    assert np.any(f[active] != f_star[active])  # the samples do tangle


def test_inactive_layers_do_not_affect_the_others():
    f_star, h_star = random_fields(41, 2000, 5)
    active, _ = active_layers(h_star)
    moved = np.where(active, f_star, f_star + np.random.default_rng(0).normal(0, 0.5, f_star.shape))
    np.testing.assert_allclose(untangle(moved, h_star)[active], untangle(f_star, h_star)[active], atol=1e-12)


def test_translation_equivariant():
    """Adding c to every f* (body included) adds c to every output; the network relies on it."""
    f_star, h_star = random_fields(42, 2000, 5)
    c = np.random.default_rng(1).uniform(-1, 1, (len(f_star), 1))
    np.testing.assert_allclose(untangle(f_star + c, h_star), untangle(f_star, h_star) + c, atol=1e-12)


def test_continuous_in_f_star():
    """A projection: 1-Lipschitz in the w-weighted norm (body equal), also for steps across kinks."""
    w = random_weights(4, 5)
    f_star, h_star = random_fields(50, 2000, 5)
    rng = np.random.default_rng(2)
    for scale in (1e-6, 1e-3, 0.1):
        step = rng.normal(0.0, scale, f_star.shape)
        step[:, 0] = 0.0
        change = untangle(f_star + step, h_star, w) - untangle(f_star, h_star, w)
        assert np.all(weighted_norm(change, w) <= weighted_norm(step, w) * (1 + 1e-9) + 1e-15)
    # along a segment through many kinks: no jumps
    t = np.linspace(0.0, 1.0, 20001)[:, None]
    a, b = np.array([0.1, 0.3, -0.1, 0.2, 0.0]), np.array([0.1, -0.2, 0.4, -0.1, 0.3])
    path = untangle(a + t * (b - a), np.full((len(t), 5), -1.0), w)
    assert np.abs(np.diff(path, axis=0)).max() <= np.abs(b - a).max() * (t[1, 0] - t[0, 0]) * 5


def test_jacobian_matches_finite_differences():
    """Continuous random inputs (no ties, so no point lies on a kink): central differences."""
    f_star, h_star = random_fields(60, 300, 5)
    f_star, h_star = np.delete(f_star, np.s_[300:600], axis=0), np.delete(h_star, np.s_[300:600], axis=0)
    w = random_weights(5, 5)
    jac, eps = untangle_jacobian(f_star, h_star, w), 1e-7
    for j in range(5):
        e = np.eye(5)[j] * eps
        fd = (untangle(f_star + e, h_star, w) - untangle(f_star - e, h_star, w)) / (2 * eps)
        np.testing.assert_allclose(jac[:, :, j], fd, rtol=0, atol=1e-6)
    assert np.allclose(jac.sum(axis=2)[~active_layers(h_star)[0]], 1.0)


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="f_star must be"):
        untangle(np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="h_star must have the shape"):
        untangle(np.zeros((2, 3)), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="must be finite"):
        untangle(np.full((2, 3), np.nan), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="weights must be"):
        untangle(np.zeros((2, 3)), np.zeros((2, 3)), np.array([1.0, np.inf, 1.0]))


# ---------------------------------------------------------------- eq. 6 taken literally, and the fit


def test_sign_only_baseline_is_feasible_for_eq6():
    f_star, h_star = random_fields(70, 1000, 5)
    f = untangle_sign_only(f_star, h_star)
    active, _ = active_layers(h_star)
    inside, outside = active & (f < 0), active & (f > 0)
    for i in range(5):
        for j in range(i + 1, 5):
            assert not np.any(inside[:, i] & outside[:, j])


def test_sign_only_leaves_a_tangled_vertex_with_zero_gradient():
    """Body at x = 0, garment 1 at x = 2 cm, garment 2 (outer) at 1 cm: crossed. A vertex of garment 2
    at x = 1.4 cm is inside garment 1. Literal eq. 6 clamps garment 2's field to 0 over a slab there:
    the fit energy f_2(x)^2 is 0 with zero gradient and the vertex never moves out. The exact operator
    gives it a nonzero gradient that pushes it outward."""

    def fields(x):
        x = np.atleast_1d(x)
        return np.stack([x, x - 0.02, x - 0.01], axis=1), -np.ones((len(x), 3))

    x, eps = np.linspace(0.0104, 0.0146, 15), 1e-6
    f_star, h_star = fields(x)
    assert np.all(f_star[:, 1] < 0) and np.all(f_star[:, 2] > 0)  # tangled

    def energy(op, x):
        return op(*fields(x))[:, 2] ** 2

    sign_only = untangle_sign_only(*fields(x))
    assert np.all(sign_only[:, 2] == 0.0)
    gradient = (energy(untangle_sign_only, x + eps) - energy(untangle_sign_only, x - eps)) / (2 * eps)
    assert np.all(gradient == 0.0)
    exact = (energy(untangle, x + eps) - energy(untangle, x - eps)) / (2 * eps)
    assert np.all(exact < -1e-3)  # descent moves the vertex to larger x, out of garment 1


def fit_two_garments(untangled, c: np.ndarray) -> np.ndarray:
    """1-D fit: along P lines the body is at x = 0 and garment k at x = c_k, f*_k(x) = x - c_k.
    Garment k's vertices (one per line, starting at c_k) minimise sum f_k(x)^2 with f the untangled
    fields. ``untangled(f_star, h_star) -> (f, d f / d f* (P, 3, >=3))``; returns x ``(P, 3)``."""
    x = c.copy()
    for k in (1, 2):

        def energy(xk, k=k):
            f, jac = untangled(xk[:, None] - c, -np.ones_like(c))
            return (f[:, k] ** 2).sum(), 2 * f[:, k] * jac[:, k, :3].sum(axis=1)  # d f*_j / dx = 1

        result = minimize(energy, x[:, k], jac=True, method="L-BFGS-B", options={"gtol": 1e-14, "ftol": 0})
        x[:, k] = result.x
    return x


def crossing_layers() -> np.ndarray:
    y = np.linspace(0.0, 2 * np.pi, 73)
    return np.stack([0 * y, 0.02 + 0.006 * np.sin(y), 0.02 + 0.006 * np.cos(y)], axis=1)


def test_fit_to_exact_fields_orders_crossing_layers_delta_apart():
    c = crossing_layers()
    tangled = c[:, 2] - c[:, 1] < GAP_DELTA
    assert tangled.any() and np.any(c[:, 2] < c[:, 1])
    x = fit_two_garments(lambda f, h: (untangle(f, h), untangle_jacobian(f, h)), c)
    gap = x[:, 2] - x[:, 1]
    assert np.all(gap >= GAP_DELTA - 1e-7)
    np.testing.assert_allclose(gap[tangled], GAP_DELTA, atol=1e-7)
    np.testing.assert_allclose(x[~tangled], c[~tangled], atol=1e-7)  # untangled lines stay
    np.testing.assert_allclose(x[tangled, 1:].mean(axis=1), c[tangled, 1:].mean(axis=1), atol=1e-7)


def test_fit_to_sign_only_fields_stays_tangled():
    c = crossing_layers()
    eps = 1e-7

    def sign_only(f, h):  # its Jacobian by central differences; every vertex moves along x only
        jac = np.stack(
            [
                (untangle_sign_only(f + e, h) - untangle_sign_only(f - e, h)) / (2 * eps)
                for e in np.eye(3) * eps
            ],
            axis=2,
        )
        return untangle_sign_only(f, h), jac

    x = fit_two_garments(sign_only, c)
    assert np.any(x[:, 2] < x[:, 1] - 1e-3)  # the outer garment still lies inside the inner one


# ---------------------------------------------------------------- neural operator (committed model)


@pytest.fixture(scope="module")
def neural() -> NeuralUntangler:
    pytest.importorskip("onnxruntime")
    return NeuralUntangler(threads=1)


def test_neural_within_stated_error_on_fresh_samples(neural):
    stated = neural.config["evaluation"]
    for k, sampler in enumerate(SAMPLERS):
        f, h = sampler(np.random.default_rng((3_000_000, k)), 20_000)
        h[:, 0] = -1.0
        err = 1e3 * np.abs(neural(f, h, jacobian=False).f - untangle(f, h, delta=neural.delta))[:, 1:]
        near = err[np.abs(f[:, 1:]) < NEAR_SURFACE].mean()
        name = sampler.__name__.removeprefix("sample_")
        assert err.mean() <= 1.25 * stated[name]["mean_mm"] + 0.02, name
        assert near <= 1.25 * stated[name]["near_surface_mean_mm"] + 0.02, name
        assert near <= ERROR_BOUND_MM, name


def test_neural_body_inactive_and_padding(neural):
    f, h = sample_layered(np.random.default_rng(80), 5000)
    h[:, 0] = 0.7  # ignored: the body is always active
    h[:, 3] = 1.0  # inactive
    out = neural(f, h, jacobian=False).f
    np.testing.assert_allclose(out[:, 0], f[:, 0], rtol=0, atol=2e-7)
    np.testing.assert_allclose(out[:, 3], f[:, 3], rtol=0, atol=2e-7)
    three = neural(f[:, :3], h[:, :3])
    assert three.f.shape == (5000, 3) and three.jacobian.shape == (5000, 3, 6)
    padded = f.copy(), h.copy()
    padded[0][:, 3:], padded[1][:, 3:] = PAD_F, PAD_H
    np.testing.assert_allclose(three.f, neural(*padded, jacobian=False).f[:, :3], atol=1e-7)


def test_neural_jacobian_matches_finite_differences(neural):
    """In float32 with steps of 10 um (f*) and 2 um (h*): the network is curved (softmax pool
    weights, up to ~1 / h_band in h* inside the blend band), so larger steps see its curvature and
    smaller ones rounding. ReLU kinks: one of forward, backward or central difference must match."""
    rng = np.random.default_rng(90)
    f, h = sample_layered(rng, 400)
    band = neural.config["config"]["h_band"]
    h[:200, 1:] = rng.uniform(-0.9, 0.9, (200, N_SLOTS - 1)) * band  # inside the blend band
    out = neural(f, h)
    assert out.jacobian.shape == (400, 5, 10)
    x = np.concatenate([f, h], axis=1)
    for j in range(10):
        eps = 1e-5 if j < N_SLOTS else 2e-6
        e = np.eye(10)[j] * eps
        plus, minus = (neural(*np.split(x + s * e, 2, axis=1), jacobian=False).f for s in (1, -1))
        jac = out.jacobian[:, :, j]
        err = np.min(
            [
                np.abs(jac - d)
                for d in ((plus - out.f) / eps, (out.f - minus) / eps, (plus - minus) / (2 * eps))
            ],
            axis=0,
        )
        assert np.all(err <= 0.01 + 0.02 * np.abs(jac)), j
    np.testing.assert_array_equal(out.jacobian[:, 0], np.tile(np.eye(10)[0], (400, 1)))  # the body row
    np.testing.assert_array_equal(out.jacobian[:, :, N_SLOTS], 0.0)  # the body's h* is ignored


def test_neural_fit_orders_crossing_layers(neural):
    """The same fit through the neural operator and its ONNX Jacobian, to its 0.5 mm error bound."""
    c = crossing_layers()
    x = fit_two_garments(lambda f, h: neural(f, h), c)
    gap, tangled, bound = x[:, 2] - x[:, 1], c[:, 2] - c[:, 1] < GAP_DELTA, 1e-3 * ERROR_BOUND_MM
    assert np.all(gap >= GAP_DELTA - bound)
    np.testing.assert_allclose(gap[tangled], GAP_DELTA, atol=bound)
    np.testing.assert_allclose(x[~tangled], c[~tangled], atol=bound)


def test_neural_row_call_equals_the_full_call_sliced(neural):
    rng = np.random.default_rng(91)
    f, h = sample_layered(rng, 2000)
    h[:1000, 1:] = rng.uniform(-0.9, 0.9, (1000, N_SLOTS - 1)) * neural.config["config"]["h_band"]
    for n in (N_SLOTS, 3):
        full = neural(f[:, :n], h[:, :n])
        for k in range(n):
            out = neural(f[:, :n], h[:, :n], row=k)
            assert out.jacobian.shape == (2000, 1, 2 * n)
            np.testing.assert_allclose(out.f, full.f, rtol=0, atol=EXPORT_TOLERANCE["f"][0])
            np.testing.assert_allclose(
                out.jacobian, full.jacobian[:, k : k + 1], *EXPORT_TOLERANCE["jacobian"][::-1]
            )
    assert neural(f, h, jacobian=False, row=2).jacobian is None
    for bad in (5, -1, True, 1.0):
        with pytest.raises(ValueError, match="row must be a layer"):
            neural(f, h, row=bad)


def test_row_graph_equals_every_row_of_the_full_graph_on_the_export_check_batch(neural):
    """What ``python -m export.untangler`` checked when it wrote ``jacobian_row.onnx``, on the
    committed files: the row graph for each one-hot row against that row of ``jacobian.onnx``."""
    pytest.importorskip("torch")
    from export.untangler import check_inputs, max_excess
    from training.untangler import UntanglerConfig, UntanglerNet

    config = neural.config["config"]
    f, h = check_inputs(UntanglerNet(UntanglerConfig(**config | {"mixture": tuple(config["mixture"])})))
    full = neural(f, h)
    for k in range(N_SLOTS):
        row = neural(f, h, row=k).jacobian[:, 0]
        assert max_excess(row, full.jacobian[:, k], EXPORT_TOLERANCE["jacobian"]) <= 0, k
    np.testing.assert_array_equal(neural(f, h, row=0).jacobian[:, 0], np.tile(np.eye(10)[0], (len(f), 1)))


def test_service_does_not_import_torch():
    modules = "service.pipeline.untangle, service.pipeline.untangle_onnx"
    code = f"import sys, {modules}; sys.exit('torch' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


def test_default_weights():
    w = default_weights(3)
    assert np.isinf(w[0]) and np.all(w[1:] == 1.0)


def test_settled_points_are_left_unchanged_by_the_projection_for_every_active_set():
    # settled == the projection with gap delta + slack, every possibly active layer active, moves
    # nothing (gaps between consecutive layers add up, so every subset is then feasible too).
    rng = np.random.default_rng(95)
    delta, band, slack = GAP_DELTA, 0.01, 0.002
    # 0.1 mm steps plus 0.03 mm per layer: no gap between two layers within 1e-5 of the bound
    f = np.round(rng.normal(scale=0.012, size=(20_000, 4)), 4) + 3e-5 * np.arange(4)
    h = rng.choice([-0.05, -0.004, 0.003, 0.05], size=f.shape)  # in and out of the band
    ok = settled(f, h, delta, band, slack)
    strict = np.where(h < band, -1.0, 1.0)
    moved = np.abs(untangle(f, strict, delta=delta + slack) - f).max(axis=1) > 1e-9
    np.testing.assert_array_equal(ok, ~moved)
    assert 0.05 < ok.mean() < 0.95
    for _ in range(8):  # any active subset the blend can see: the exact operator is the identity
        active = np.where((h < band) & (rng.random(f.shape) < 0.5), -1.0, 1.0)
        np.testing.assert_allclose(untangle(f[ok], active[ok], delta=delta), f[ok], rtol=0, atol=1e-12)


def test_screened_is_the_network_where_something_can_move_and_the_identity_elsewhere(neural):
    rng = np.random.default_rng(96)
    f, h = sample_layered(rng, 4000)
    h[:2000, 1:] = rng.uniform(-2, 2, (2000, N_SLOTS - 1)) * neural.h_band
    f[::3, 1:] = f[::3, :1] - np.arange(1, N_SLOTS) * 0.02  # well apart: settled
    ok = settled(f, h, neural.delta, neural.h_band, SETTLED_SLACK)
    assert 0.2 < ok.mean() < 0.8
    for n in (N_SLOTS, 3):
        fn, hn = f[:, :n], h[:, :n]
        ok = settled(fn, hn, neural.delta, neural.h_band, SETTLED_SLACK)
        full, plain = neural.screened(fn, hn), neural(fn[~ok], hn[~ok])
        np.testing.assert_array_equal(full.f[~ok], plain.f)
        np.testing.assert_array_equal(full.jacobian[~ok], plain.jacobian)
        np.testing.assert_array_equal(full.f[ok], fn[ok])
        np.testing.assert_array_equal(full.jacobian[ok], np.tile(np.eye(n, 2 * n), (ok.sum(), 1, 1)))
        # The network agrees with the identity at settled points far from every blend band.
        clear = ok & np.all((np.abs(hn[:, 1:]) > 2 * neural.h_band), axis=1)
        assert np.abs(neural(fn[clear], hn[clear], jacobian=False).f - fn[clear]).max() < 1e-3
        for k in range(n):
            row = neural.screened(fn, hn, row=k)
            np.testing.assert_array_equal(row.f, full.f)
            np.testing.assert_array_equal(row.jacobian[~ok], neural(fn[~ok], hn[~ok], row=k).jacobian)
            np.testing.assert_array_equal(row.jacobian[ok, 0], np.tile(np.eye(2 * n)[k], (ok.sum(), 1)))
        assert neural.screened(fn, hn, jacobian=False).jacobian is None
    with pytest.raises(ValueError, match="row must be a layer"):
        neural.screened(f, h, row=7)
    everything = neural.screened(f[:0], h[:0])  # no points at all
    assert everything.f.shape == (0, N_SLOTS)


def test_neural_batches_on_two_threads_agree_with_one_call_on_one(neural, monkeypatch):
    """The committed operator cut into batches on two threads: one call's answer, bit for bit (with
    one intra-op thread per session a point's answer does not depend on its batch)."""
    from service.pipeline import untangle_onnx

    rng = np.random.default_rng(11)
    f = rng.normal(0, 0.01, (6000, 4))
    h = rng.normal(0, 0.05, (6000, 4))
    one = untangle_onnx.NeuralUntangler(threads=1)
    two = untangle_onnx.NeuralUntangler(threads=2)
    monkeypatch.setattr(untangle_onnx, "BATCH", 1500)
    for kwargs in ({"jacobian": False}, {"jacobian": True}, {"jacobian": True, "row": 2}):
        a, b = two(f, h, **kwargs), one(f, h, **kwargs)
        np.testing.assert_array_equal(a.f, b.f)
        if b.jacobian is not None:
            np.testing.assert_array_equal(a.jacobian, b.jacobian)
