"""The issue-55 study's pure parts (training/body_coverage.py): the bounded Levenberg-Marquardt fit on toy
models, the tolerance test, the region tally of self-intersections. No Anny here (fast)."""

from __future__ import annotations

import numpy as np
import pytest

from training.body_coverage import VARIANTS, face_region_pairs, fit, start_point, within_tolerance


def linear(a: np.ndarray, b: np.ndarray):
    calls = []

    def forward(x: np.ndarray) -> np.ndarray:
        calls.append(len(x))
        return x @ a.T + b

    return forward, calls


def test_fit_recovers_known_parameters_of_a_linear_model():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(4, 4)), rng.normal(size=4)
    truth = np.array([0.3, -0.7, 1.2, 0.05])
    forward, calls = linear(a, b)
    scales = np.array([0.5, 1.0, 1.0, 2.0])
    targets = forward(truth[None])[0]
    calls.clear()
    r = fit(forward, targets, scales, np.zeros(4), -np.full(4, 5), np.full(4, 5), stop=1e-6)
    np.testing.assert_allclose(r.x, truth, atol=1e-5)
    assert np.all(np.abs(r.residuals) < 1e-6)
    assert within_tolerance(r.residuals)
    assert calls[0] == 5  # the point and its four forward differences in one batch
    assert r.evaluations == sum(calls)


def test_fit_recovers_a_nonlinear_model_and_keeps_to_the_bounds():
    def forward(x):
        return np.column_stack([x[:, 0] ** 3 + x[:, 1], np.exp(x[:, 1]) * x[:, 0]])

    truth = np.array([1.1, 0.4])
    targets = forward(truth[None])[0]
    r = fit(
        forward,
        targets,
        np.ones(2),
        np.array([0.5, 0.0]),
        np.array([0.0, -1.0]),
        np.array([2.0, 1.0]),
        stop=1e-7,
    )
    np.testing.assert_allclose(r.x, truth, atol=1e-5)
    # the truth outside the box: the fit ends on the bound, not beyond it
    r = fit(forward, targets, np.ones(2), np.array([0.5, 0.0]), np.array([0.0, -1.0]), np.array([1.0, 1.0]))
    assert r.x[0] <= 1.0 and r.x[1] <= 1.0
    assert not within_tolerance(r.residuals / 1e-3)


def test_the_ridge_pins_down_what_the_targets_do_not():
    # two parameters, one target that sees only their sum: the ridge on the second keeps it at its prior
    forward, _ = linear(np.array([[1.0, 1.0]]), np.zeros(1))
    r = fit(
        forward,
        np.array([2.0]),
        np.array([1e-3]),
        np.zeros(2),
        -np.full(2, 9),
        np.full(2, 9),
        prior=np.array([0.0, 0.5]),
        ridge=np.array([0.0, 1.0]),
        stop=1e-3,
        gradient_stop=1e-8,
    )
    np.testing.assert_allclose(r.x, [1.5, 0.5], atol=1e-4)


def test_fit_refuses_a_failing_start_point():
    def forward(x):
        return np.full((len(x), 1), np.nan)

    with pytest.raises(ValueError, match="start point"):
        fit(forward, np.zeros(1), np.ones(1), np.zeros(1), -np.ones(1), np.ones(1))


def test_within_tolerance_is_inclusive():
    assert within_tolerance(np.array([1.0, -1.0, 0.0]))
    assert not within_tolerance(np.array([1.0001]))


def test_face_region_pairs_sorts_and_counts_region_pairs():
    faces = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8]])
    regions = np.array([0, 0, 0, 1, 1, 1, 2, 2, 2], dtype=np.uint8)
    names = ("torso", "upperleg_l", "upperleg_r")
    counts = face_region_pairs(np.array([[1, 2], [2, 1], [0, 1]]), faces, regions, names)
    assert counts == {"upperleg_l/upperleg_r": 2, "torso/upperleg_l": 1}


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_start_points_lie_in_each_variants_box(name):
    v = VARIANTS[name]
    for gender, height, bmi in ((0.0, 140.0, 14.0), (1.0, 200.0, 70.0), (1.0, 165.0, 25.0)):
        x = start_point(v, gender, height, bmi)
        assert x.shape == (len(v.params),)
        assert np.all(x >= v.lower) and np.all(x <= v.upper)
