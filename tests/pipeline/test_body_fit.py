"""Tests of the extended body shape (``service.pipeline.body``: extrapolated phenotypes, local changes)
and of the fit of a shape to a tape measure (``service.pipeline.body_fit``), on the committed model."""

from __future__ import annotations

import numpy as np
import pytest

from service.pipeline.body import (
    DEFAULT_BETA,
    SHAPE_BOUNDS,
    BodyModel,
    _hat_segments,
    body_measurements,
    hat_coefficients,
    shape_coefficients,
)
from service.pipeline.body_fit import (
    GIVEN_SCALE,
    QUANTITIES,
    TOLERANCE,
    Target,
    carried_levels,
    evaluate,
    fit_shape,
    measured_rows,
)
from service.pipeline.measurements import landmarks, measure

# Shapes inside SHAPE_BOUNDS: a heavy short woman, a thin tall man, a heavy man with a belly (no local
# change at exactly 0, where its derivative is one-sided and central differences average the sides).
SHAPES = (
    (1.0, 0.35, 1.8, -0.5, 0.3, 0.5, 0.2, 0.1, 0.2),
    (0.0, 0.65, -0.3, 0.2, -0.4, 0.05, -0.3, -0.2, -0.1),
    (0.0, 0.45, 1.4, 0.6, -0.8, 0.3, 0.4, 0.1, 1.2),
)


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return BodyModel.load()


@pytest.fixture(scope="module")
def marks(body):
    return landmarks(body)


def test_extended_shape_without_changes_is_the_box_body(body):
    """Inside Anny's anchors and with no local change, the extended shape is the old body, bit for bit
    up to the blend's rounding."""
    for beta in np.random.default_rng(3).uniform(size=(5, 3)):
        np.testing.assert_allclose(body.shape_vertices(body.as_shape(beta)), body.vertices(beta), atol=1e-12)


def test_extrapolated_hats_continue_the_end_segments():
    """1.5 is twice the last segment's width past its start (0.5): -1 x anchor 0.5 + 2 x anchor 1."""
    anchors = np.array([0.0, 0.5, 1.0])
    outside, _ = _hat_segments(np.array([1.5, -0.5]), anchors, extrapolate=True)
    np.testing.assert_allclose(outside, [[0.0, -1.0, 2.0], [2.0, -1.0, 0.0]])
    np.testing.assert_allclose(
        _hat_segments(np.array([0.75]), anchors, extrapolate=True)[0],
        hat_coefficients(np.array([0.75]), anchors),
    )


def test_shape_coefficients_jacobian_matches_finite_differences(body):
    shapes = np.array(SHAPES)
    _, jac = shape_coefficients(shapes, body.anchors, body.n_local)
    eps = 1e-6
    for k in range(shapes.shape[1]):
        step = np.zeros(shapes.shape[1])
        step[k] = eps
        plus, _ = shape_coefficients(shapes + step, body.anchors, body.n_local)
        minus, _ = shape_coefficients(shapes - step, body.anchors, body.n_local)
        np.testing.assert_allclose(jac[:, k], (plus - minus) / (2 * eps), atol=1e-6)


def test_local_changes_are_signed_targets(body):
    """+1 adds the "-incr" displacement, -1 the "-decr" one; the two differ (not a mirror)."""
    base = body.as_shape(np.array(DEFAULT_BETA))
    for i in range(body.n_local):
        for sign, side in ((1.0, 0), (-1.0, 1)):
            shape = base.copy()
            shape[3 + i] = 2.0 * sign
            moved = body.shape_vertices(shape) - body.shape_vertices(base)
            np.testing.assert_allclose(moved, 2.0 * body.local_deltas[i, side], atol=1e-12)


def test_shape_checks_bounds_and_shape(body):
    lo = np.array([b[0] for b in SHAPE_BOUNDS])
    with pytest.raises(ValueError, match="weight"):
        body.shape_vertices(np.where(np.arange(len(lo)) == 2, 2.6, np.maximum(lo, 0.0)))
    with pytest.raises(ValueError, match=r"\(9,\)"):
        body.shape_vertices(np.zeros(3))
    with pytest.raises(ValueError, match="finite"):
        body.shape_vertices(np.full(9, np.nan))


@pytest.mark.parametrize("shape", SHAPES)
def test_evaluate_matches_the_mesh_and_finite_differences(body, marks, shape):
    """Height and weight as ``body_measurements`` reads them off the mesh; girths as ``measure`` at
    the levels it picked; every Jacobian column to central differences at those carried levels."""
    shape = np.array(shape)
    v = body.shape_vertices(shape)
    measured = measure(v, body.faces, marks)
    levels = carried_levels(v, marks, measured)
    rows = measured_rows(QUANTITIES, {tape: [level] for tape, level in levels.items()})
    values, jac = evaluate(body, marks, shape, rows)
    assert [n for n, _ in rows] == list(QUANTITIES)
    height_m, mass_kg = body_measurements(v, body.faces)
    np.testing.assert_allclose(values[:2], [100.0 * height_m, mass_kg], rtol=1e-10)
    np.testing.assert_allclose(values[2:], [getattr(measured, q) for q in QUANTITIES[2:]], atol=1e-9)
    eps = 1e-6
    for k in range(1, len(shape)):
        step = np.zeros(len(shape))
        step[k] = eps
        fd = (evaluate(body, marks, shape + step, rows)[0] - evaluate(body, marks, shape - step, rows)[0]) / (
            2 * eps
        )
        assert np.all(np.abs(jac[:, k] - fd) <= 2e-4 * (1.0 + np.abs(fd))), (k, jac[:, k], fd)


@pytest.mark.parametrize("shape", SHAPES)
def test_fit_recovers_a_body_from_its_own_measurements(body, marks, shape):
    """Given the height, weight, hip and iliac waist of a known body, the fit builds a body measuring
    them within their tolerances (``measure``, the levels picked again), from a plain start."""
    truth = measure(body.shape_vertices(np.array(shape)), body.faces, marks)
    given = ("height_cm", "weight_kg", "hip_cm", "waist_iliac_cm")
    targets = {q: Target(getattr(truth, q), GIVEN_SCALE * TOLERANCE[q]) for q in given}
    start = np.zeros(len(shape))
    start[:3] = (shape[0], 0.5, 0.5)
    fit = fit_shape(body, marks, start, targets, frozenset(given))
    assert fit.reproduced, fit
    for q in given:
        tolerance = TOLERANCE[q] * (getattr(truth, q) if q == "weight_kg" else 1.0)
        assert abs(getattr(fit.measured, q) - getattr(truth, q)) <= tolerance
    assert fit.shape[0] == shape[0]  # gender kept
