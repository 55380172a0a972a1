"""Tests of a shopper's body from measurements (``service.pipeline.body_build``) and of the girth
predictions it rests on (``service.pipeline.girth_priors``), on the committed models."""

from __future__ import annotations

import math

import numpy as np
import pytest

from service.geometry.self_contact import self_crossings
from service.pipeline.body import SHAPE_BOUNDS, SUPPORTED_HEIGHT_PARAM, BodyModel, ShapeOutOfRange
from service.pipeline.body_build import (
    BMI_RANGE,
    GIRTHS,
    HEIGHT_RANGE_CM,
    BodyBuilder,
    BodyRequest,
    garment_code,
    weight_range_kg,
)
from service.pipeline.body_fit import TOLERANCE
from service.pipeline.body_table import TABLE_NAME, BodyTable
from service.pipeline.girth_priors import MODELS, GirthPriors
from service.pipeline.measurements import measure
from service.process.paths import models_dir

# Real-looking requests: a heavy short woman with her hip, a tall thin man, a woman giving all three
# girths, a heavy man giving his waist.
REQUESTS = (
    BodyRequest(1.0, 152.0, 105.0, hip_cm=132.0),
    BodyRequest(0.0, 196.0, 68.0),
    BodyRequest(1.0, 166.0, 68.0, chest_cm=96.0, waist_cm=76.0, hip_cm=104.0),
    BodyRequest(0.0, 175.0, 120.0, waist_cm=118.0),
)


@pytest.fixture(scope="module")
def builder() -> BodyBuilder:
    return BodyBuilder(BodyModel.load(), GirthPriors.load())


def _within(measured: float, target: float, name: str) -> bool:
    return abs(measured - target) <= TOLERANCE[name] * (target if name == "weight_kg" else 1.0)


@pytest.mark.parametrize("request_", REQUESTS)
def test_given_measurements_are_reproduced_and_missing_ones_reported(builder, request_):
    built = builder.build(request_)
    for name in ("height_cm", "weight_kg", *request_.given):
        assert _within(getattr(built.measured, name), getattr(request_, name), name), name
    report = built.report()
    assert report["predicted"] == sorted(set(GIRTHS) - set(request_.given))
    assert set(built.predicted) <= {"chest_cm", "hip_cm", "waist_iliac_cm"}
    assert "waist_iliac_cm" not in built.predicted or "waist_cm" not in request_.given
    lo, hi = np.array(SHAPE_BOUNDS).T
    assert np.all((built.shape >= lo) & (built.shape <= hi))
    # The garments' code is the default-phenotype body of her gender, height and weight (the heavy
    # woman's weight phenotype past the box's 1), what the population drapes were trained on.
    assert SUPPORTED_HEIGHT_PARAM[0] <= built.garment_beta[1] <= SUPPORTED_HEIGHT_PARAM[1]
    np.testing.assert_array_equal(built.garment_beta, garment_code(builder.model, builder.marks, request_))
    if request_.weight_kg / (request_.height_cm / 100.0) ** 2 > 40.0:
        assert built.garment_beta[2] > 1.0
    assert builder.build(request_) is built  # kept


def test_a_fit_stalled_at_its_rule_of_thumb_start_is_tried_again_from_the_table():
    """A tall heavy man giving chest and hip: from ``start_shape`` the fit stalls at its first step
    and is refused 12 kg short (without the table); from the table's body of his height and weight it
    reproduces them."""
    model, priors = BodyModel.load(), GirthPriors.load()
    request = BodyRequest(0.0, 189.8, 120.0, chest_cm=123.5, hip_cm=127.5)
    with pytest.raises(ShapeOutOfRange):
        BodyBuilder(model, priors).build(request)
    built = BodyBuilder(model, priors, BodyTable.load(models_dir() / "body" / TABLE_NAME)).build(request)
    for name in ("height_cm", "weight_kg", "chest_cm", "hip_cm"):
        assert _within(getattr(built.measured, name), getattr(request, name), name), name


# The heaviest held-out NHANES adults (benchmarks.population's BMI tail, 2017-2020): their inner thighs,
# breasts and belly cross as Anny grows them, and are pressed into contact.
HEAVY = (
    BodyRequest(1.0, 166.0, 180.1, hip_cm=176.9),  # BMI 65
    BodyRequest(1.0, 161.0, 156.6, hip_cm=160.0),  # BMI 60
    BodyRequest(0.0, 171.0, 157.3),  # BMI 54, no girth: the fit without the table
)


@pytest.mark.parametrize("request_", HEAVY)
def test_a_heavy_body_is_one_surface_that_does_not_cross_itself(builder, request_):
    """Pressed (``self_contact``): nothing crosses outside Anny's own toes, the given measurements are
    still reproduced on the pressed mesh, which is what the report measures."""
    built = builder.build(request_)
    model = builder.model
    assert built.pressed is not None and built.pressed.crossings == 0
    assert len(self_crossings(built.vertices, model.faces, model.template_crossings)) == 0
    assert len(self_crossings(model.shape_vertices(built.shape), model.faces, model.template_crossings)) > 0
    tape = measure(built.vertices, model.faces, builder.marks)
    for name in ("height_cm", "weight_kg", *request_.given):
        assert _within(getattr(tape, name), getattr(request_, name), name), name
        assert getattr(built.measured, name) == getattr(tape, name)


def test_predicted_girths_are_met_about_as_well_as_the_prediction_knows_them(builder):
    """A missing hip is fitted softly to its prediction: within one prediction sd."""
    request_ = BodyRequest(1.0, 165.0, 80.0)
    built = builder.build(request_)
    prediction = builder.priors.predict(1.0, 165.0, 80.0, {})["hip_cm"]
    assert abs(built.measured.hip_cm - prediction.value_cm) < prediction.sd_cm


@pytest.mark.parametrize(
    ("request_", "field", "text"),
    [
        (BodyRequest(1.2, 165.0, 60.0), "gender", "0-1"),
        (BodyRequest(1.0, 120.0, 60.0), "height_cm", "135.0-210.0"),
        (BodyRequest(1.0, 165.0, 20.0), "weight_kg", "BMI 13-70"),
        (BodyRequest(1.0, 165.0, 200.0), "weight_kg", "for height_cm=165"),
        (BodyRequest(1.0, 165.0, float("nan")), "weight_kg", "finite"),
        (BodyRequest(1.0, 165.0, 60.0, hip_cm=300.0), "hip_cm", "adults of height_cm=165"),
        (BodyRequest(0.0, 175.0, 150.0, waist_cm=60.0), "waist_cm", "adults"),
        (BodyRequest(1.0, 165.0, 60.0, chest_cm="wide"), "chest_cm", "not a number"),
    ],
)
def test_refusals_name_the_field_and_what_is_allowed(builder, request_, field, text):
    with pytest.raises(ShapeOutOfRange, match=text) as err:
        builder.build(request_)
    assert err.value.field == field


def test_a_girth_refusal_range_is_accepted_at_its_bounds(builder):
    """The printed range of a girth given height and weight: its bounds pass the check (the body may
    still not reach a bound: the body fit decides), and a value 1 cm beyond is refused."""
    ranges = builder.ranges(1.0, 165.0, 70.0)
    lo, hi = ranges["hip_cm"]
    with pytest.raises(ShapeOutOfRange, match="hip_cm"):
        builder.build(BodyRequest(1.0, 165.0, 70.0, hip_cm=hi + 1.0))
    assert ranges["height_cm"] == HEIGHT_RANGE_CM
    assert ranges["weight_kg"] == pytest.approx(weight_range_kg(165.0), abs=0.1)
    assert lo < 100.0 < hi


def test_weight_range_is_the_bmi_range():
    lo, hi = weight_range_kg(170.0)
    assert lo / 1.7**2 == pytest.approx(BMI_RANGE[0]) and hi / 1.7**2 == pytest.approx(BMI_RANGE[1])


def test_priors_mix_the_sexes_and_grow_with_weight():
    priors = GirthPriors.load()
    for target, _ in MODELS.items():
        at = {g: priors.predict(g, 170.0, 70.0, {})[target].value_cm for g in (0.0, 0.5, 1.0)}
        assert at[0.5] == pytest.approx(math.sqrt(at[0.0] * at[1.0]), rel=1e-9)  # mixed in log space
        heavier = priors.predict(1.0, 170.0, 90.0, {})[target].value_cm
        assert heavier > at[1.0]
    with_chest = priors.predict(1.0, 165.0, 70.0, {"chest_cm": 110.0})["hip_cm"]
    assert with_chest.model == "hip_cm|chest_cm"
    coef = priors.models["female|hip_cm|chest_cm"]["coef"]
    expected = math.exp(np.dot(coef, [1.0, math.log(165.0), math.log(70.0), math.log(110.0)]))
    assert with_chest.value_cm == pytest.approx(expected, rel=1e-12)
