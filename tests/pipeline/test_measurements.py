"""Tests of ``service/pipeline/measurements.py``: landmarks found exactly on a synthetic torso (a stack
of similar ellipses whose widest and narrowest rings are known), and plausible, weight-monotone
girths on the committed Anny body (``models/body/anny_shape.npz``)."""

from __future__ import annotations

import numpy as np
import pytest

from service.geometry.girth import polyline_length
from service.pipeline.body import (
    DEFAULT_BETA,
    BodyModel,
    body_measurements,
    shape_from_measurements,
    supported_weight_range_kg,
)
from service.pipeline.measurements import ARM_BAND_M, STEP_M, TAPES, Landmarks, Level, landmarks, measure
from service.process.paths import REPO_ROOT
from tests.geometry.test_girth import ellipse, stack

BODY_PATH = REPO_ROOT / "models" / "body" / "anny_shape.npz"


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return BodyModel.load(BODY_PATH)


@pytest.fixture(scope="module")
def marks(body) -> Landmarks:
    return landmarks(body)


# ---------------------------------------------------------------- a synthetic torso

# Rings every STEP_M from z = 0: scale 0.8 at the crotch, widest at ring 8 (hip), narrowest at ring 30
# (natural waist, between the iliac ring 20 and the rib ring 36), widest again at ring 50 (chest).
N_RINGS, N_AROUND = 61, 64
KNOTS, SCALES = [0, 8, 30, 50, 60], [0.8, 1.0, 0.7, 1.05, 0.9]
HIP, WAIST, ILIAC, RIBS, CHEST = 8, 30, 20, 36, 50


def synthetic_torso():
    """(vertices, faces, landmarks, ring polygons (K, N, 2)) of a stack of similar ellipses: the
    perimeter is linear between rings, so the extremes lie on rings, which lie on the search grid."""
    scale = np.interp(np.arange(N_RINGS), KNOTS, SCALES)
    rings = scale[:, None, None] * ellipse(0.16, 0.11, N_AROUND, centre=(0.0, -0.02))[None]
    v, f = stack(rings, STEP_M * np.arange(N_RINGS))
    ring = np.arange(N_RINGS * N_AROUND).reshape(N_RINGS, N_AROUND)
    marks = Landmarks(
        torso=ring.ravel(),
        crotch=np.array([len(v) - 2]),  # the bottom cap's centre
        arms=(),
        iliac=Level(ring[ILIAC], 0.0),
        ribs=Level(ring[RIBS], 0.0),
        shoulders=Level(ring[-1], 0.0),
    )
    return v, f, marks, rings


def test_landmarks_of_a_synthetic_torso_are_found_exactly():
    v, f, marks, rings = synthetic_torso()
    m = measure(v, f, marks)
    for name, k in (("hip", HIP), ("waist", WAIST), ("chest", CHEST), ("waist_iliac", ILIAC)):
        assert m.levels_m[name] == pytest.approx(k * STEP_M, abs=1e-12), name
        assert getattr(m, f"{name}_cm") == pytest.approx(100 * polyline_length(rings[k]), rel=1e-12), name
    assert m.height_cm == pytest.approx(100 * STEP_M * (N_RINGS - 1))
    assert m.chest_cm > m.hip_cm > m.waist_iliac_cm > m.waist_cm


def test_the_search_bands_bound_the_landmarks():
    """Moving the lowest ribs below the narrowest ring puts the natural waist on the ribs' ring; the
    hip and chest bands follow the waist."""
    v, f, marks, rings = synthetic_torso()
    low_ribs = Landmarks(
        marks.torso,
        marks.crotch,
        marks.arms,
        marks.iliac,
        Level(marks.ribs.vertices, -0.0525),
        marks.shoulders,
    )
    m = measure(v, f, low_ribs)
    assert m.levels_m["waist"] == pytest.approx(25 * STEP_M)  # the ribs at ring 25.5, the narrowest ring 30
    assert m.waist_cm == pytest.approx(100 * polyline_length(rings[25]), rel=1e-12)
    assert m.levels_m["hip"] == pytest.approx(HIP * STEP_M) and m.levels_m["chest"] == pytest.approx(
        CHEST * STEP_M
    )


def test_an_arm_beside_the_chest_stops_the_chest_search():
    """An arm close beside the torso above ring 40 (the tape would bridge onto it): the chest is taken
    below that, where the tape still goes round the torso alone."""
    v, f, marks, rings = synthetic_torso()
    # Arm vertices: a column whose centre at each height from ring 40.5 up is just inside the torso's hull.
    heights = STEP_M * np.arange(40.5, N_RINGS)
    arm_points = np.stack([np.full_like(heights, 0.1), np.full_like(heights, -0.02), heights], 1)
    v2 = np.concatenate([v, arm_points])
    arm = np.arange(len(v), len(v2))
    m = measure(v2, f, Landmarks(marks.torso, marks.crotch, (arm,), marks.iliac, marks.ribs, marks.shoulders))
    # The arm counts from ARM_BAND_M below its lowest point; below that the perimeter rises to the
    # last grid height before it.
    first_with_arm = 40.5 * STEP_M - ARM_BAND_M
    assert m.levels_m["chest"] == pytest.approx(STEP_M * np.floor(first_with_arm / STEP_M))
    assert m.levels_m["chest"] < first_with_arm


def test_landmarks_out_of_order_raise():
    v, f, marks, _ = synthetic_torso()
    swapped = Landmarks(marks.torso, marks.crotch, marks.arms, marks.ribs, marks.iliac, marks.shoulders)
    with pytest.raises(ValueError, match="out of order"):
        measure(v, f, swapped)
    with pytest.raises(ValueError):
        measure(v[:, :2], f, marks)


# ---------------------------------------------------------------- the Anny body


def test_default_body_is_plausible(body, marks):
    v = body.vertices(np.array(DEFAULT_BETA))
    m = measure(v, body.faces, marks)
    height_m, mass_kg = body_measurements(v, body.faces)
    assert m.height_cm == pytest.approx(100 * height_m) and m.weight_kg == pytest.approx(mass_kg)
    assert m.chest_cm > m.waist_cm and m.hip_cm > m.waist_cm
    assert m.hip_cm > m.waist_iliac_cm > m.waist_cm
    # Adult girths (cm) and their order in height: hip below the waist below the chest.
    for name in TAPES:
        assert 50 < getattr(m, f"{name}_cm") < 150
    levels = m.levels_m
    assert levels["hip"] < levels["waist_iliac"] <= levels["waist"] < levels["chest"]
    # Each tape lies on the body at its height, inside the torso's width (no arm in it).
    for name in TAPES:
        tape = m.tapes[name]
        assert np.all(tape[:, 2] == levels[name])
        assert np.abs(tape[:, 0]).max() < 0.25
        assert 100 * polyline_length(tape[:, :2]) == pytest.approx(getattr(m, f"{name}_cm"))


@pytest.mark.parametrize(("gender", "height_cm"), [(0.0, 160.0), (0.0, 185.0), (1.0, 155.0), (1.0, 175.0)])
def test_girths_grow_with_weight(body, marks, gender, height_cm):
    lo, hi = supported_weight_range_kg(body, gender, height_cm)
    rows = []
    for weight_kg in np.linspace(lo, hi, 4):
        m = measure(
            body.vertices(shape_from_measurements(body, gender, height_cm, weight_kg)), body.faces, marks
        )
        assert m.height_cm == pytest.approx(height_cm, abs=0.01) and m.weight_kg == pytest.approx(
            weight_kg, abs=0.01
        )
        assert m.chest_cm > m.waist_cm and m.hip_cm > m.waist_cm and m.waist_iliac_cm > m.waist_cm
        rows.append([m.chest_cm, m.waist_cm, m.hip_cm, m.waist_iliac_cm])
    assert np.all(np.diff(np.array(rows), axis=0) > 0), np.round(rows, 1)


def test_women_have_wider_hips_than_waists_relative_to_men(body, marks):
    """Waist-to-hip ratio, the classic sex difference: lower for a woman than a man of the same BMI."""
    ratio = {}
    for gender, height_cm in ((0.0, 178.0), (1.0, 165.0)):
        weight_kg = 22.0 * (height_cm / 100) ** 2
        m = measure(
            body.vertices(shape_from_measurements(body, gender, height_cm, weight_kg)), body.faces, marks
        )
        ratio[gender] = m.waist_cm / m.hip_cm
    assert ratio[1.0] < ratio[0.0]
