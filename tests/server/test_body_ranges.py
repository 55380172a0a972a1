"""Height and weight ranges: the bounds a refusal prints are accepted, and a value one printed step
beyond either is refused (the committed body model)."""

from __future__ import annotations

import pytest

from service.pipeline.body import (
    BodyModel,
    ShapeOutOfRange,
    printed_bounds,
    shape_from_measurements,
    supported_height_range_cm,
    supported_weight_range_kg,
)

STEP = 0.1  # the printed precision (service.pipeline.body.RANGE_DECIMALS)


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return BodyModel.load()


def refusal(body: BodyModel, gender: float, height_cm: float, weight_kg: float) -> str | None:
    try:
        shape_from_measurements(body, gender, height_cm, weight_kg)
    except ShapeOutOfRange as e:
        return str(e)
    return None


@pytest.mark.parametrize(
    ("gender", "heights"), [(0.0, (149.5, 214.8)), (0.5, (142.5, 207.7)), (1.0, (135.7, 200.8))]
)
def test_printed_height_bounds_are_accepted_and_one_step_beyond_refused(body, gender, heights):
    lo, hi = heights
    assert printed_bounds(*supported_height_range_cm(body, gender)) == heights
    weight = sum(supported_weight_range_kg(body, gender, (lo + hi) / 2)) / 2
    for height in heights:
        w_lo, w_hi = printed_bounds(*supported_weight_range_kg(body, gender, height))
        assert refusal(body, gender, height, (w_lo + w_hi) / 2) is None
    range_ = f"{lo:.1f}-{hi:.1f} cm for gender={gender:g}"
    for height in (round(lo - STEP, 1), round(hi + STEP, 1)):
        assert refusal(body, gender, height, weight) == (
            f"height_cm={height:g} is outside the supported range {range_}"
        )


@pytest.mark.parametrize(
    ("gender", "height", "weights"),
    [(1.0, 135.6, None), (1.0, 135.7, (25.8, 51.8)), (0.0, 214.8, (89.7, 153.9)), (0.0, 150.0, (38.8, 74.8)),
     (1.0, 165.0, (40.9, 76.7)), (1.0, 200.8, (66.1, 116.0))],
)  # fmt: skip
def test_printed_weight_bounds_are_accepted_and_one_step_beyond_refused(body, gender, height, weights):
    if weights is None:  # the woman of 135.6 cm of issue 54: below the 135.7 cm the message prints
        assert refusal(body, gender, height, 40.0) == (
            "height_cm=135.6 is outside the supported range 135.7-200.8 cm for gender=1"
        )
        return
    assert printed_bounds(*supported_weight_range_kg(body, gender, height)) == weights
    lo, hi = weights
    assert refusal(body, gender, height, lo) is None and refusal(body, gender, height, hi) is None
    for weight in (round(lo - STEP, 1), round(hi + STEP, 1)):
        assert refusal(body, gender, height, weight) == (
            f"weight_kg={weight:g} is outside the supported range {lo:.1f}-{hi:.1f} kg "
            f"for gender={gender:g}, height_cm={height:g}"
        )


@pytest.mark.parametrize(
    ("lo", "hi", "printed"),
    [(135.6358, 200.8298, (135.7, 200.8)), (89.6, 154.0, (89.6, 154.0)), (0.3000001, 0.7, (0.4, 0.7))],
)
def test_printed_bounds_round_inwards(lo, hi, printed):
    assert printed_bounds(lo, hi) == printed
    assert lo <= printed[0] and printed[1] <= hi


def test_the_ranges_endpoint_answers_what_the_engine_accepts(client):
    """FakeEngine's made-up girth ranges (tests/service_tools.py), the real heights and BMIs."""
    response = client.get("/v1/body/ranges", params={"gender": 1, "height_cm": 165, "weight_kg": 60})
    assert response.status_code == 200
    assert response.json() == {
        "gender": 1.0, "height_cm": {"min": 135.0, "max": 210.0}, "weight_kg": {"min": 35.4, "max": 190.5},
        "weight_at_height_cm": 165.0, "chest_cm": {"min": 61.5, "max": 102.0},
        "waist_cm": {"min": 50.3, "max": 93.7}, "hip_cm": {"min": 61.5, "max": 102.0},
        "girths_at_weight_kg": 60.0,
    }  # fmt: skip
    # a weight outside the range at this height: the girths at the weight moved into it
    heavy = client.get("/v1/body/ranges", params={"height_cm": 150, "weight_kg": 300}).json()
    assert heavy["weight_kg"] == {"min": 29.3, "max": 157.5} and heavy["girths_at_weight_kg"] == 157.5
    middle = client.get("/v1/body/ranges").json()
    assert middle["height_cm"] == {"min": 135.0, "max": 210.0} and middle["weight_at_height_cm"] == 172.5
    assert middle["girths_at_weight_kg"] == (middle["weight_kg"]["min"] + middle["weight_kg"]["max"]) / 2


def test_the_ranges_endpoint_names_a_bad_parameter(client):
    response = client.get("/v1/body/ranges", params={"gender": 2})
    assert response.status_code == 422
    error = {"field": "query.gender", "message": "Input should be less than or equal to 1",
             "allowed": "a number from 0 (male) to 1 (female)"}  # fmt: skip
    assert response.json() == {"detail": "query.gender: Input should be less than or equal to 1 (allowed: a "
                               "number from 0 (male) to 1 (female))", "errors": [error]}  # fmt: skip


@pytest.mark.parametrize("weight_kg", [None, 60.0, 150.0])
def test_the_real_engines_ranges_are_accepted_at_their_bounds(weight_kg):
    """ModelEngine.body_ranges over the committed body model and girth priors: every printed bound is
    accepted and one printed step beyond it refused, with the refusal naming the same range."""
    from service.pipeline.body_build import BodyRequest as Shopper
    from service.pipeline.body_build import check_request
    from tests.server.apps import body_engine

    engine = body_engine()
    ranges = engine.body_ranges(1.0, 165.0, weight_kg)
    assert ranges["height_cm"] == (135.0, 210.0) and ranges["weight_kg"] == (35.4, 190.5)
    assert ranges["at_height_cm"] == 165.0 and engine.body_ranges(0.0, 300.0)["at_height_cm"] == 210.0
    w = ranges["at_weight_kg"]
    assert w == (weight_kg if weight_kg is not None else (35.4 + 190.5) / 2)
    priors = engine.models.bodies.priors
    for name in ("chest_cm", "waist_cm", "hip_cm"):
        lo, hi = ranges[name]
        assert 0 < lo < hi
        for value in (lo, hi):
            check_request(priors, Shopper(1.0, 165.0, w, **{name: value}))
        for value in (round(lo - STEP, 1), round(hi + STEP, 1)):
            with pytest.raises(ShapeOutOfRange, match=f"outside the range {lo:.1f}-{hi:.1f} cm"):
                check_request(priors, Shopper(1.0, 165.0, w, **{name: value}))
