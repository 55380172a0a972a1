"""POST /v1/outfits and GET /v1/outfits/{id}.glb at the HTTP edge (fake engine, tiny catalog):
content negotiation, cache, validation messages, size limit, overload and deadlines."""

from __future__ import annotations

import asyncio
import json
import logging
import threading
import time
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient

from service.server.logs import JsonFormatter
from tests.server.apps import make_app
from tests.service_tools import live_server, wait_until

GLB = "model/gltf-binary"
TINY = {"garments": ["pants", "tshirt"], "body": {"gender": 0.0, "height_cm": 180, "weight_kg": 80}}


def test_post_answers_json_with_a_glb_url(app_and_engine):
    client, engine = app_and_engine
    response = client.post("/v1/outfits", json=TINY)
    assert response.status_code == 200
    body = response.json()
    assert set(body) == {"id", "glb_url", "cached", "report"}
    assert len(body["id"]) == 32
    query = "garments=pants,tshirt&gender=0&height_cm=180&weight_kg=80&v=fake"
    assert body["glb_url"] == f"/v1/outfits.glb?{query}"
    assert body["cached"] is False and body["report"]["garments"] == ["pants", "tshirt"]
    glb = client.get(body["glb_url"])
    assert glb.status_code == 200 and glb.headers["content-type"] == GLB
    assert glb.content[:4] == b"glTF" and glb.headers["etag"] == f'"{body["id"]}"'
    again = client.post("/v1/outfits", json=TINY).json()
    assert again["id"] == body["id"] and again["cached"] is True
    assert engine["it"].calls == 1
    assert 'ulnef_outfit_cache_total{result="hit"} 2.0' in client.get("/metrics").text


def test_an_outfit_left_with_crossings_says_so_and_is_counted(fake_models_dir: Path):
    app, _ = make_app(fake_models_dir, crossings=3)
    with TestClient(app) as client:
        assert app.state.tryon.wait_loaded(10)
        report = client.post("/v1/outfits", json=TINY).json()["report"]
        assert report["collision_free"] is False and report["crossing_pairs"] == 3
        assert "ulnef_outfit_with_crossings_total 1.0" in client.get("/metrics").text
        client.post("/v1/outfits", json=TINY)  # from the cache: counted once, when computed
        assert "ulnef_outfit_with_crossings_total 1.0" in client.get("/metrics").text


def test_post_answers_the_glb_itself_for_accept_glb(client: TestClient):
    response = client.post("/v1/outfits", json=TINY, headers={"Accept": GLB})
    assert response.status_code == 200
    assert response.headers["content-type"] == GLB and response.content[:4] == b"glTF"
    outfit_id = response.headers["x-outfit-id"]
    assert response.headers["content-location"].startswith("/v1/outfits.glb?garments=pants,tshirt&")
    assert client.get(response.headers["content-location"]).content == response.content
    assert client.get(f"/v1/outfits/{outfit_id}.glb").content == response.content


@pytest.mark.parametrize(
    ("accept", "expected"),
    [(None, "application/json"), ("*/*", "application/json"), ("application/json", "application/json"),
     (GLB, GLB), (f"{GLB}, */*", GLB), (f"application/json;q=0.5, {GLB}", GLB), ("model/*", GLB),
     (f"{GLB};q=0.1, application/json", "application/json")],
)  # fmt: skip
def test_accept_negotiation(client: TestClient, accept, expected):
    headers = {"Accept": accept} if accept else {}
    assert client.post("/v1/outfits", json=TINY, headers=headers).headers["content-type"] == expected


def test_unacceptable_accept_is_406(client: TestClient):
    response = client.post("/v1/outfits", json=TINY, headers={"Accept": "text/html"})
    assert response.status_code == 406
    error = {"field": "header.accept", "message": "'text/html' allows neither answer",
             "allowed": f"application/json (default) or {GLB}"}  # fmt: skip
    assert response.json() == {"detail": f"header.accept: 'text/html' allows neither answer (allowed: "
                               f"application/json (default) or {GLB})", "errors": [error]}  # fmt: skip


def test_same_outfit_same_id_whatever_the_spelling(client: TestClient):
    a = client.post("/v1/outfits", json={"garments": ["tshirt"]}).json()["id"]
    b = client.post("/v1/outfits", json={"garments": ["tshirt"], "options": {"untangle": True},
                                         "body": {"height_cm": 178.0}}).json()["id"]  # fmt: skip
    c = client.post("/v1/outfits", json={"garments": ["tshirt"], "body": {"height_cm": 179}}).json()["id"]
    assert a == b != c


def test_unknown_glb_is_404(client: TestClient):
    response = client.get("/v1/outfits/" + "0" * 32 + ".glb")
    assert response.status_code == 404
    assert response.json() == {"detail": f"outfit {'0' * 32} is not in this replica's cache (evicted, made "
                                         "elsewhere, or never made): GET the `glb_url` of POST /v1/outfits "
                                         "instead"}  # fmt: skip


def test_evicted_outfit_is_404_by_id_and_made_again_by_url(fake_models_dir: Path):
    app, engine = make_app(fake_models_dir, cache_entries=1)
    with TestClient(app) as client:
        app.state.tryon.wait_loaded(10)
        first = client.post("/v1/outfits", json={"garments": ["tshirt"]}).json()
        client.post("/v1/outfits", json={"garments": ["pants"]})
        assert client.get(f"/v1/outfits/{first['id']}.glb").status_code == 404
        again = client.get(first["glb_url"])
        assert again.status_code == 200 and again.headers["x-outfit-id"] == first["id"]
        assert engine["it"].calls == 3


ALLOWED_GARMENTS = ("a list of 1-4 distinct garments, inner to outer, each a garment id or `{\"id\": ..., "
                    "\"size\": ...}` (GET /v1/garments lists the ids and each one's sizes): tshirt, pants")
ALLOWED_SIZE = ("one of XS, S, M, L, XL, XXL where the garment comes in sizes (GET /v1/garments), or null: "
                "the one-size garment cut to the body")  # fmt: skip
ALLOWED_REQUEST = "a JSON object with `garments` (required), `body` and `options`"
ID_RULE = "ids are 1-32 lower case letters, digits and _, starting with a letter"
ALLOWED_WEIGHT = "a number from 23.6 to 308.7; the exact range depends on height (BMI 13-70)"
ALLOWED_GIRTH = ("a number above 0, or null (predicted from height and weight when missing); the exact range "
                 "depends on gender, height and weight (GET /v1/body/ranges)")  # fmt: skip


# (request body, field, message, allowed): also asked as GLB URLs (tests/server/test_outfit_url.py)
BAD_INPUT = [
    ({"garments": ["cape"]}, "garments", "unknown id(s) ['cape']",
     "1-4 distinct ids, inner to outer, from: tshirt, pants"),
    ({"garments": []}, "garments", "List should have at least 1 item after validation, not 0",
     ALLOWED_GARMENTS),
    ({"garments": ["tshirt"] * 5}, "garments", "List should have at most 4 items after validation, not 5",
     ALLOWED_GARMENTS),
    ({"garments": ["tshirt", "tshirt"]}, "garments", "repeated id(s) ['tshirt']",
     ALLOWED_GARMENTS),
    ({"garments": [3]}, "garments.0", "Input should be a garment id or an object with `id` and `size`",
     ALLOWED_GARMENTS),
    ({"garments": [{"id": "tshirt", "size": "XXXL"}]}, "garments.0.size",
     "Input should be 'XS', 'S', 'M', 'L', 'XL' or 'XXL'", ALLOWED_SIZE),
    ({"garments": ["pants", {"id": "tshirt", "size": "m"}]}, "garments.1.size",
     "Input should be 'XS', 'S', 'M', 'L', 'XL' or 'XXL'", ALLOWED_SIZE),
    ({"garments": [{"id": "pants", "size": "M"}]}, "garments.0.size", "'pants' comes in one size",
     "no size for 'pants' (garments with sizes: tshirt)"),
    ({"garments": [{"size": "M"}]}, "garments.0.id", "Field required",
     "a garment id (GET /v1/garments): tshirt, pants"),
    ({"garments": [{"id": "tshirt", "size": "M", "fit": "slim"}]}, "garments.0.fit", "unknown field",
     ALLOWED_GARMENTS.removesuffix(": tshirt, pants")),
    ({"garments": [{"id": "T!", "size": "M"}]}, "garments.0.id", f"unknown garment id 'T!' ({ID_RULE})",
     "a garment id (GET /v1/garments): tshirt, pants"),
    ({"garments": ["tshirt", {"id": "tshirt", "size": "M"}]}, "garments", "repeated id(s) ['tshirt']",
     ALLOWED_GARMENTS),
    ({"garments": "tshirt"}, "garments", "Input should be a valid list", ALLOWED_GARMENTS),
    ({"garments": ["T-Shirt!"]}, "garments.0", f"unknown garment id 'T-Shirt!' ({ID_RULE})",
     ALLOWED_GARMENTS),
    ({"garments": ["pants", "TShirt"]}, "garments.1", f"unknown garment id 'TShirt' ({ID_RULE})",
     ALLOWED_GARMENTS),
    ({"garments": ["a" * 33]}, "garments.0", f"unknown garment id '{'a' * 33}' ({ID_RULE})",
     ALLOWED_GARMENTS),
    # the longest id the rule allows (and `ulnef garments import` takes): not in this catalog
    ({"garments": ["a" * 32]}, "garments", f"unknown id(s) ['{'a' * 32}']",
     "1-4 distinct ids, inner to outer, from: tshirt, pants"),
    ({"body": {}}, "garments", "Field required", ALLOWED_GARMENTS),
    ({"garments": ["tshirt"], "body": {"gender": 2}}, "body.gender",
     "Input should be less than or equal to 1", "a number from 0 (male) to 1 (female)"),
    ({"garments": ["tshirt"], "body": {"gender": True}}, "body.gender", "Input should be a valid number",
     "a number from 0 (male) to 1 (female)"),
    ({"garments": ["tshirt"], "body": {"height_cm": "180"}}, "body.height_cm",
     "Input should be a valid number", "a number from 135 to 210"),
    ({"garments": ["tshirt"], "body": {"height_cm": 211}}, "body.height_cm",
     "Input should be less than or equal to 210", "a number from 135 to 210"),
    ({"garments": ["tshirt"], "body": {"weight_kg": -1}}, "body.weight_kg",
     "Input should be greater than or equal to 23.6", ALLOWED_WEIGHT),
    ({"garments": ["tshirt"], "body": {"height_cm": 150, "weight_kg": 300}}, "body.weight_kg",
     "weight_kg=300 is outside the supported range 29.3-157.5 kg for height_cm=150 (BMI 13-70)",
     "29.3-157.5"),
    ({"garments": ["tshirt"], "body": {"chest_cm": "90"}}, "body.chest_cm", "Input should be a valid number",
     ALLOWED_GIRTH),
    ({"garments": ["tshirt"], "body": {"hip_cm": -5}}, "body.hip_cm", "Input should be greater than 0",
     ALLOWED_GIRTH),
    ({"garments": ["tshirt"], "body": {"waist_cm": 0}}, "body.waist_cm", "Input should be greater than 0",
     ALLOWED_GIRTH),
    ({"garments": ["tshirt"], "body": {"waist_cm": True}}, "body.waist_cm", "Input should be a valid number",
     ALLOWED_GIRTH),
    # girths possible at this height and weight: FakeEngine's made-up ranges, the real engine's message
    ({"garments": ["tshirt"], "body": {"gender": 1, "height_cm": 165, "weight_kg": 60, "hip_cm": 300}},
     "body.hip_cm", "hip_cm=300 is outside the range 61.5-102.0 cm that adults of height_cm=165 and "
     "weight_kg=60 have", "61.5-102.0"),
    ({"garments": ["tshirt"], "body": {"height_cm": 165, "weight_kg": 60, "waist_cm": 93, "hip_cm": 62}},
     "body.waist_cm", "no body has waist_cm, hip_cm together as given (waist_cm=93, hip_cm=62)",
     "a combination a body has"),
    ({"garments": ["tshirt"], "body": {"age": 30}}, "body.age", "unknown field",
     "an object with `gender`, `height_cm`, `weight_kg` and, each optional, `chest_cm`, `waist_cm`, "
     "`hip_cm`"),
    ({"garments": ["tshirt"], "options": {"untangle": "yes"}}, "options.untangle",
     "Input should be a valid boolean", "true or false"),
    ({"garments": ["tshirt"], "options": {"untangler": "magic"}}, "options.untangler",
     "Input should be 'neural' or 'reference'", "`neural` or `reference`"),
    ({"garments": ["tshirt"], "options": {"speed": 1}}, "options.speed", "unknown field",
     "an object with `untangle`, `include_body`, `measure`, `untangler`, `compression`, `tension`"),
    ({"garments": ["tshirt"], "options": {"tension": True, "compression": "meshopt"}}, "options.tension",
     "the tension map is in the plain encoding only (compression 'meshopt')",
     "true or false; true only with `compression` `none`"),
    ({"garments": ["tshirt"], "colour": "red"}, "colour", "unknown field", ALLOWED_REQUEST),
    (["tshirt"], "(request body)", "Input should be a valid dictionary or object to extract fields from",
     ALLOWED_REQUEST),
]  # fmt: skip


@pytest.mark.parametrize(("body", "field", "message", "allowed"), BAD_INPUT)
def test_bad_input_names_the_field_and_what_it_allows(client, body, field, message, allowed):
    response = client.post("/v1/outfits", json=body)
    assert response.status_code == 422, response.text
    error = {"field": field, "message": message, "allowed": allowed}
    assert error in response.json()["errors"], response.json()
    assert response.json()["detail"].startswith(f"{field}: {message} (allowed: {allowed})")


@pytest.mark.parametrize("name", ["height_cm", "chest_cm", "hip_cm"])
@pytest.mark.parametrize("value", ["NaN", "Infinity", "-Infinity", "1e999"])
def test_non_finite_numbers_are_refused(client: TestClient, value, name):
    raw = '{"garments": ["tshirt"], "body": {"NAME": VALUE}}'.replace("VALUE", value).replace("NAME", name)
    response = client.post("/v1/outfits", content=raw, headers={"Content-Type": "application/json"})
    assert response.status_code == 422, response.text
    assert response.json()["errors"][0]["field"] == f"body.{name}"


def test_malformed_json(client: TestClient):
    headers = {"Content-Type": "application/json"}
    response = client.post("/v1/outfits", content=b'{"garments": [', headers=headers)
    assert response.status_code == 422
    (error,) = response.json()["errors"]
    assert error["field"] == "(request body)" and error["message"].startswith("malformed JSON")


def test_body_that_is_not_utf8(client: TestClient):
    headers = {"Content-Type": "application/json"}
    response = client.post("/v1/outfits", content=b"\xff\xfe\xfa", headers=headers)
    assert response.status_code == 422
    (error,) = response.json()["errors"]
    assert error == {"field": "(request body)", "message": "malformed JSON (not UTF-8 text)",
                     "allowed": ALLOWED_REQUEST}  # fmt: skip


def test_oversized_body_is_413_with_or_without_content_length(client: TestClient):
    big = b'{"garments": ["tshirt"], "pad": "' + b"x" * 20_000 + b'"}'
    allowed = "at most 16384 bytes (setting ULNEF_MAX_BODY_BYTES)"
    expected = {"detail": f"request body too large: {allowed}", "errors": [
        {"field": "(request body)", "message": "request body too large", "allowed": allowed}]}
    response = client.post("/v1/outfits", content=big, headers={"Content-Type": "application/json"})
    assert response.status_code == 413 and response.json() == expected

    def chunks():
        for i in range(0, len(big), 4096):
            yield big[i : i + 4096]

    streamed = client.post("/v1/outfits", content=chunks(), headers={"Content-Type": "application/json"})
    assert streamed.status_code == 413 and streamed.json() == expected


def test_a_body_that_is_not_json_is_415(client: TestClient):
    response = client.post("/v1/outfits", content=b"garments=tshirt", headers={"Content-Type": "text/plain"})
    assert response.status_code == 415
    error = {"field": "header.content-type", "message": "'text/plain' is not JSON",
             "allowed": "application/json (or a +json type)"}  # fmt: skip
    assert response.json() == {"detail": "header.content-type: 'text/plain' is not JSON (allowed: "
                               "application/json (or a +json type))", "errors": [error]}  # fmt: skip
    typed = client.post("/v1/outfits", content=json.dumps(TINY),
                        headers={"Content-Type": "application/json; charset=utf-8"})  # fmt: skip
    assert typed.status_code == 200


def test_bad_outfit_id_is_422(client: TestClient):
    response = client.get("/v1/outfits/not-an-id.glb")
    assert response.status_code == 422
    assert response.json()["errors"][0]["field"] == "path.outfit_id"


def test_deadline_answers_504_and_the_service_recovers(fake_models_dir: Path):
    release = threading.Event()  # the outfit takes until the test lets it finish
    app, engine = make_app(fake_models_dir, request_timeout_s=0.2, release=release)
    with TestClient(app) as client:
        assert app.state.tryon.wait_loaded(10)
        response = client.post("/v1/outfits", json=TINY)
        assert engine["it"].started.is_set() and not release.is_set()  # answered while still making it
        assert response.status_code == 504 and response.headers["retry-after"] == "5"
        assert response.json() == {"detail": "deadline exceeded: no outfit within the 0.2 s time budget"}
        assert len(app.state.tryon.cache) == 0
        release.set()  # the job finishes in the background and fills the cache
        wait_until(lambda: len(app.state.tryon.cache) == 1, 10, "the late outfit never reached the cache")
        assert client.post("/v1/outfits", json=TINY).json()["cached"] is True


def test_burst_gets_timely_answers_and_a_bounded_queue(fake_models_dir: Path):
    """60 distinct requests at once on 1 worker + 2 queue places (0.2 s each): a few are served, the
    rest refused at once with 503 + Retry-After; no request waits past its deadline."""
    app, engine = make_app(fake_models_dir, delay=0.2, workers=1, queue_size=2, request_timeout_s=5)

    async def burst(base: str):
        async with httpx.AsyncClient(base_url=base, timeout=10) as http:

            async def one(i: int):
                t0 = time.perf_counter()
                body = {"garments": ["tshirt"], "body": {"height_cm": 140 + i}}
                r = await http.post("/v1/outfits", json=body)
                return r, time.perf_counter() - t0

            return await asyncio.gather(*(one(i) for i in range(60)))

    with live_server(app) as base:
        answers = asyncio.run(burst(base))
        codes = [r.status_code for r, _ in answers]
        assert set(codes) <= {200, 503}, codes
        assert 3 <= codes.count(200) < 20, codes
        refused = [r for r, _ in answers if r.status_code == 503]
        assert all(int(r.headers["retry-after"]) >= 1 for r in refused)
        assert refused[0].json()["detail"].startswith("overloaded: ")
        assert max(seconds for _, seconds in answers) < 5
        assert engine["it"].calls == codes.count(200)
        assert app.state.tryon.worker.pending == 0
        metrics = httpx.get(f"{base}/metrics").text
        assert "ulnef_queue_depth 0.0" in metrics
        assert httpx.get(f"{base}/healthz").status_code == 200


def test_each_request_is_one_json_log_line(client: TestClient, caplog):
    caplog.set_level(logging.INFO, logger="service.access")
    response = client.post("/v1/outfits", json={"garments": ["cape"]})
    (record,) = [r for r in caplog.records if r.name == "service.access"]
    line = json.loads(JsonFormatter().format(record))
    assert line["message"] == "request" and line["level"] == "info"
    assert line["route"] == "/v1/outfits" and line["status"] == 422 and line["method"] == "POST"
    assert line["request_id"] == response.headers["x-request-id"] and line["ms"] >= 0
