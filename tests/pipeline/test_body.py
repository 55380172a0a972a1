"""Tests of ``service/pipeline/body.py`` on the committed ``models/body/anny_shape.npz``.

Refresh the npz with ``python -m export.body``. Only the parity test (marked ``anny``) imports
Anny; every other test runs on numpy alone.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from service.pipeline.body import (
    BODY_DENSITY_KG_M3,
    DEFAULT_BETA,
    SUPPORTED_HEIGHT_PARAM,
    SUPPORTED_WEIGHT_PARAM,
    BodyModel,
    ShapeOutOfRange,
    body_measurements,
    hat_coefficients,
    hat_slopes,
    measurements_from_shape,
    mesh_volume,
    shape_from_measurements,
    supported_height_range_cm,
    supported_weight_range_kg,
)
from service.process.paths import REPO_ROOT

BODY_PATH = REPO_ROOT / "models" / "body" / "anny_shape.npz"
GENDERS = (0.0, 0.5, 1.0)
GRID = 7  # requests per axis in the calibration grid


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return BodyModel.load(BODY_PATH)


def _random_betas(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(size=(n, 3))


def _requests(body: BodyModel, gender: float):
    """(height_cm, weight_kg) grid spanning the supported range, bounds included."""
    lo, hi = supported_height_range_cm(body, gender)
    for height_cm in np.linspace(lo, hi, GRID):
        for weight_kg in np.linspace(*supported_weight_range_kg(body, gender, height_cm), GRID):
            yield float(height_cm), float(weight_kg)


# ---------------------------------------------------------------- parity and math


@pytest.mark.anny
def test_vertices_match_anny_on_random_shapes(body):
    from export.body import parity_errors_mm

    err = parity_errors_mm(body, _random_betas(100, seed=7))
    assert err.max() < 1.0  # mm; the export check holds 0.1 mm, float32 storage gives ~1e-4


@pytest.mark.parametrize("anchors", [np.array([0.0, 1.0]), np.array([0.0, 0.5, 1.0])])
def test_hat_coefficients_match_piecewise_linear_reference(anchors):
    x = np.concatenate([np.linspace(-0.2, 1.2, 57), anchors])
    reference = np.stack([np.interp(x, anchors, np.eye(len(anchors))[i]) for i in range(len(anchors))], 1)
    np.testing.assert_allclose(hat_coefficients(x, anchors), reference, atol=1e-15)
    inside = np.linspace(0.013, 0.987, 20)  # avoids the anchors, where the slope is one-sided
    h = 1e-7
    fd = (hat_coefficients(inside + h, anchors) - hat_coefficients(inside - h, anchors)) / (2 * h)
    np.testing.assert_allclose(hat_slopes(inside, anchors), fd, atol=1e-6)


def test_fast_height_mass_equals_mesh_measurements(body):
    betas = np.concatenate([_random_betas(20, seed=1), np.array([[0, 0, 0], [1, 1, 1], [0, 1, 0.5]])])
    height, mass, _ = body.height_mass(betas)
    reference = np.array([body_measurements(v, body.faces) for v in body.vertices_batch(betas)])
    np.testing.assert_allclose(height, reference[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(mass, reference[:, 1], rtol=1e-12)


def test_height_mass_jacobian_matches_finite_differences(body):
    # Away from the weight anchor 0.5, where the derivative jumps.
    betas = np.array([[0.2, 0.3, 0.2], [0.7, 0.6, 0.8], [0.5, 0.45, 0.35]])
    _, _, jac = body.height_mass(betas)
    h = 1e-6
    for k in range(3):
        step = np.zeros(3)
        step[k] = h
        hp, mp, _ = body.height_mass(betas + step)
        hm, mm, _ = body.height_mass(betas - step)
        np.testing.assert_allclose(jac[:, 0, k], (hp - hm) / (2 * h), atol=1e-6)
        np.testing.assert_allclose(jac[:, 1, k], (mp - mm) / (2 * h), rtol=1e-6, atol=1e-4)


def test_mass_is_volume_times_density(body):
    vertices = body.vertices(np.array(DEFAULT_BETA))
    height_m, mass_kg = body_measurements(vertices, body.faces)
    assert mass_kg == pytest.approx(mesh_volume(vertices, body.faces) * BODY_DENSITY_KG_M3)
    assert height_m == pytest.approx(vertices[:, 2].max() - vertices[:, 2].min())


# ---------------------------------------------------------------- mesh and metadata


def test_random_bodies_are_watertight_and_outward(body):
    for beta in _random_betas(5, seed=2):
        mesh = trimesh.Trimesh(body.vertices(beta), body.faces, process=False)
        assert mesh.is_watertight
        assert mesh.is_winding_consistent
        assert mesh.volume > 0
        assert mesh_volume(mesh.vertices, body.faces) == pytest.approx(mesh.volume, rel=1e-9)


def test_model_arrays_and_regions(body):
    assert body.faces.dtype == np.int64 and body.faces.shape[1] == 3
    assert body.regions.shape == (body.n_vertices,) and body.regions.dtype == np.uint8
    assert set(np.unique(body.regions)) == set(range(len(body.region_names)))
    assert len(body.bone_names) == len(body.bone_heads) and body.bone_heads.shape[1] == 3
    assert body.metadata["fixed_phenotypes"] == {
        "age": pytest.approx(2 / 3),
        "muscle": 0.25,
        "proportions": 0.5,
    }
    vertices = body.vertices(np.array(DEFAULT_BETA))

    def centroid(region: str) -> np.ndarray:
        return vertices[body.regions == body.region_names.index(region)].mean(axis=0)

    assert centroid("hand_l")[0] > 0 > centroid("hand_r")[0]  # the body's left is +X
    assert centroid("head")[2] > centroid("torso")[2] > centroid("upperleg_l")[2] > centroid("foot_l")[2]


def test_load_default_path_and_missing_file(monkeypatch, tmp_path):
    monkeypatch.delenv("ULNEF_MODELS_DIR", raising=False)
    assert BodyModel.load().n_vertices == 13348
    monkeypatch.setenv("ULNEF_MODELS_DIR", str(tmp_path))
    with pytest.raises(FileNotFoundError, match="python -m export.body"):
        BodyModel.load()


# ---------------------------------------------------------------- beta checks


@pytest.mark.parametrize("beta", [np.zeros(2), np.zeros((1, 3)), np.zeros(4), np.zeros((3, 1))])
def test_vertices_rejects_bad_beta_shape(body, beta):
    with pytest.raises(ValueError, match=r"beta must be \(3,\) \(gender, height, weight\), got shape"):
        body.vertices(beta)


@pytest.mark.parametrize("betas", [np.zeros(3), np.zeros((2, 4)), np.zeros((2, 3, 1))])
def test_vertices_batch_rejects_bad_beta_shape(body, betas):
    with pytest.raises(ValueError, match=r"beta must be \(B, 3\)"):
        body.vertices_batch(betas)


def test_beta_values_are_checked(body):
    with pytest.raises(ValueError, match="beta must be finite"):
        body.vertices(np.array([0.5, np.nan, 0.5]))
    with pytest.raises(ValueError, match=r"beta must lie in \[0, 1\].*out of range: height, weight$"):
        body.vertices_batch(np.array([[0.5, 0.5, 0.5], [0.5, 1.2, -0.1]]))
    with pytest.raises(ValueError, match=r"beta must be \(3,\)"):
        measurements_from_shape(body, np.zeros((1, 3)))


# ---------------------------------------------------------------- calibration


@pytest.mark.parametrize("gender", GENDERS)
def test_calibration_hits_requested_height_and_mass(body, gender):
    for height_cm, weight_kg in _requests(body, gender):
        beta = shape_from_measurements(body, gender, height_cm, weight_kg)
        height_m, mass_kg = body_measurements(body.vertices(beta), body.faces)
        assert abs(100 * height_m - height_cm) < 1.0
        assert abs(mass_kg - weight_kg) < 0.5
        assert beta[0] == gender
        assert SUPPORTED_HEIGHT_PARAM[0] - 1e-4 <= beta[1] <= SUPPORTED_HEIGHT_PARAM[1] + 1e-4
        assert SUPPORTED_WEIGHT_PARAM[0] - 1e-4 <= beta[2] <= SUPPORTED_WEIGHT_PARAM[1] + 1e-4
        assert measurements_from_shape(body, beta) == pytest.approx((height_cm, weight_kg), abs=1e-3)


@pytest.mark.parametrize("gender", GENDERS)
def test_calibration_is_monotone(body, gender):
    lo, hi = supported_height_range_cm(body, gender)
    height_cm = (lo + hi) / 2
    weights_kg = np.linspace(*supported_weight_range_kg(body, gender, height_cm), 9)
    betas = np.array([shape_from_measurements(body, gender, height_cm, m) for m in weights_kg])
    masses = [body_measurements(body.vertices(b), body.faces)[1] for b in betas]
    assert np.all(np.diff(masses) > 0)
    assert np.all(np.diff(betas[:, 2]) > 0)

    heights_cm = np.linspace(lo, hi, 9)
    mid_weights = [np.mean(supported_weight_range_kg(body, gender, h)) for h in heights_cm]
    betas = np.array(
        [shape_from_measurements(body, gender, h, m) for h, m in zip(heights_cm, mid_weights, strict=True)]
    )
    assert np.all(np.diff(betas[:, 1]) > 0)


def test_supported_ranges_cover_common_adults(body):
    for gender in (0.0, 1.0):
        lo, hi = supported_height_range_cm(body, gender)
        assert lo <= 150.0 and hi >= 200.0
    # Regression values of the committed npz (python -m benchmarks.body_parity prints more).
    assert supported_weight_range_kg(body, 0.0, 175.0) == pytest.approx((55.04, 101.18), abs=0.01)
    assert supported_weight_range_kg(body, 1.0, 165.0) == pytest.approx((40.81, 76.77), abs=0.01)


# ---------------------------------------------------------------- rejected requests


def test_height_out_of_range_names_field_and_range(body):
    lo, hi = supported_height_range_cm(body, 0.0)
    with pytest.raises(ShapeOutOfRange) as info:
        shape_from_measurements(body, 0.0, 230, 80)
    assert (
        str(info.value) == f"height_cm=230 is outside the supported range {lo:.1f}-{hi:.1f} cm for gender=0"
    )
    assert info.value.field == "height_cm" and info.value.allowed == (lo, hi)
    assert isinstance(info.value, ValueError)


def test_weight_out_of_range_names_field_and_range(body):
    lo, hi = supported_weight_range_kg(body, 1.0, 165.0)
    for weight_kg in (lo - 0.5, hi + 0.5):
        with pytest.raises(ShapeOutOfRange) as info:
            shape_from_measurements(body, 1.0, 165.0, weight_kg)
        assert str(info.value) == (
            f"weight_kg={weight_kg:g} is outside the supported range 40.9-76.7 kg "
            "for gender=1, height_cm=165"
        )
        assert info.value.field == "weight_kg"


@pytest.mark.parametrize("gender", [-0.1, 1.5])
def test_gender_out_of_range(body, gender):
    with pytest.raises(ShapeOutOfRange, match=rf"^gender={gender:g} is outside the supported range 0-1"):
        shape_from_measurements(body, gender, 170, 70)
    with pytest.raises(ShapeOutOfRange, match="^gender="):
        supported_height_range_cm(body, gender)


@pytest.mark.parametrize(
    ("request_", "field", "text"),
    [
        ((np.nan, 170, 70), "gender", "gender=nan is not a finite number"),
        ((0.0, np.inf, 70), "height_cm", "height_cm=inf is not a finite number"),
        ((0.0, 170, -np.inf), "weight_kg", "weight_kg=-inf is not a finite number"),
        ((0.0, 170, "heavy"), "weight_kg", "weight_kg='heavy' is not a number"),
        ((0.0, None, 70), "height_cm", "height_cm=None is not a number"),
    ],
)
def test_non_finite_requests_are_rejected(body, request_, field, text):
    with pytest.raises(ShapeOutOfRange) as info:
        shape_from_measurements(body, *request_)
    assert str(info.value) == text
    assert info.value.field == field and info.value.allowed is None
