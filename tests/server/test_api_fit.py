"""POST /v1/fit (issue 56): each size of a style on a shopper's body, and the size to buy, on the
committed models; and every bad input a 422 naming its field and what is allowed."""

from __future__ import annotations

import json

import pytest
from fastapi.testclient import TestClient

from service.pipeline.sizes import LETTERS, chart
from service.pipeline.tryon import ModelEngine
from service.process.paths import models_dir
from service.server.app import create_app
from service.server.settings import Settings

STYLES = ("tank_top", "tshirt", "long_sleeve", "jacket", "pants", "shorts", "skirt")


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    engine = ModelEngine.load(models_dir(), threads=1)
    # a body fit takes 0.3-1 s alone, longer on a loaded machine: no deadline under test here
    settings = Settings(models_dir=tmp_path_factory.mktemp("models"), verify_models=False,
                        configure_logging=False, self_test_garments=[], request_timeout_s=600)  # fmt: skip
    app = create_app(settings, lambda s: engine)
    with TestClient(app) as c:
        assert app.state.tryon.wait_loaded(30)
        yield c


def chart_body(run: str, letter: str) -> dict:
    """The API body of a chart size's centre: its height, girths and the weight it was built at."""
    charts = json.loads((models_dir() / "garments" / "size_charts.json").read_text())
    request = charts[f"{run}/{letter}"]["request"]
    return {k: request[k] for k in ("gender", "height_cm", "weight_kg", "chest_cm", "waist_cm", "hip_cm")}


@pytest.mark.parametrize("letter", ("S", "L"))
def test_a_body_at_a_chart_sizes_centre_is_recommended_that_size(client: TestClient, letter: str):
    body = chart_body("men", letter)
    answer = client.post("/v1/fit", json={"style": "tshirt", "body": body})
    assert answer.status_code == 200, answer.text
    fit = answer.json()
    assert fit["recommended"]["size"] == letter and fit["recommended"]["fits"]
    assert (fit["style"], fit["run"], fit["under"]) == ("tshirt", "men", [])
    assert list(fit["sizes"]) == list(LETTERS)
    row = next(r for r in chart("men") if r.letter == letter)
    assert abs(fit["body"]["chest_cm"] - row.chest_cm) <= 1.0 and fit["body"]["predicted"] == []
    # Each size up is roomier everywhere; its own size has the design ease at the chest within 2 cm.
    for region in fit["design_ease_cm"]:
        eases = [fit["sizes"][s]["regions"][region]["ease_cm"] for s in LETTERS]
        assert all(b > a for a, b in zip(eases, eases[1:], strict=False)), region
    own = fit["sizes"][letter]["regions"]["chest"]
    assert abs(own["ease_cm"] - fit["design_ease_cm"]["chest"]) <= 2.0
    assert own["ease_cm"] == pytest.approx(own["garment_cm"] - own["under_cm"], abs=0.11)


def test_layers_under_a_jacket_take_its_room(client: TestClient):
    body = {"gender": 0, "height_cm": 178, "weight_kg": 80}
    fits = [client.post("/v1/fit", json={"style": "jacket", "under": under, "body": body}).json()
            for under in ([], ["tank_top"], ["tshirt"], ["tank_top", "tshirt"])]  # fmt: skip
    chest = [f["sizes"]["L"]["regions"]["chest"]["ease_cm"] for f in fits]
    # Each layer lies on the body alone (its explicit model): a tank top under a T-shirt takes no more
    # room than the T-shirt where the T-shirt is loose over it.
    assert chest[0] > chest[1] and chest[0] > chest[2] >= chest[3] and chest[1] > chest[2], chest
    # over the body alone the size chart's reckoning is the same whatever is under
    assert len({f["sizes"]["L"]["regions"]["chest"]["body_ease_cm"] for f in fits}) == 1
    assert fits[2]["under"] == ["tshirt"]


@pytest.mark.parametrize(
    ("payload", "field", "allowed"),
    [
        ({"style": "hat"}, "style", "one of " + ", ".join(sorted(STYLES))),
        ({"style": "Hat!"}, "style", "a garment id with sizes (GET /v1/garments)"),
        ({}, "style", "a garment id with sizes (GET /v1/garments)"),
        ({"style": "jacket", "under": ["hat"]}, "under", "1-3 distinct ids, inner to outer, from: "),
        ({"style": "jacket", "under": ["jacket"]}, "under", "garment ids worn under the style"),
        ({"style": "jacket", "under": ["tshirt", "tshirt"]}, "under", "a list of 0-3 distinct garment ids"),
        ({"style": "jacket", "under": ["tank_top", "tshirt", "long_sleeve", "pants"]}, "under",
         "a list of 0-3 distinct garment ids"),
        ({"style": "pants", "under": ["skirt"]}, "under", "an order cloth can take"),
        ({"style": "jacket", "body": {"height_cm": 300}}, "body.height_cm", "a number from 135 to 210"),
        ({"style": "jacket", "size": "M"}, "size", "a JSON object with `style` (required)"),
    ],
)  # fmt: skip
def test_bad_input_is_a_422_naming_the_field_and_what_is_allowed(client, payload, field, allowed):
    response = client.post("/v1/fit", json=payload)
    assert response.status_code == 422, response.text
    errors = response.json()["errors"]
    assert errors[0]["field"] == field, errors
    assert errors[0]["allowed"].startswith(allowed), errors
