"""GLB URLs that carry their request (``service.server.outfit_url``): any replica answers them with
the same bytes, they validate like the POST, and they cache like immutable files (ETag, 304)."""

from __future__ import annotations

import gzip
import json
from pathlib import Path
from urllib.parse import parse_qsl, urlencode, urlsplit

import pytest
from fastapi.testclient import TestClient

from service.pipeline.tryon import GIRTH_FIELDS, OutfitSpec
from service.server.outfit_url import glb_url, parse_query
from service.server.schemas import ALLOWED
from tests.server.apps import make_app
from tests.server.test_api_outfits import BAD_INPUT, GLB, TINY

IMMUTABLE = "public, max-age=31536000, immutable"


@pytest.fixture
def replicas(fake_models_dir: Path):
    """Two apps over the same models that share nothing else (two replicas), and their engines."""
    (a, ea), (b, eb) = make_app(fake_models_dir), make_app(fake_models_dir)
    with TestClient(a) as one, TestClient(b) as two:
        assert a.state.tryon.wait_loaded(10) and b.state.tryon.wait_loaded(10)
        yield (one, ea), (two, eb)


def test_url_round_trips_to_the_same_request():
    spec = OutfitSpec(("pants", "tshirt"), 0.25, 180.5, 80.0, untangle=False, untangler="reference")
    url = glb_url(spec, "meshopt", "v1")
    assert url == ("/v1/outfits.glb?garments=pants,tshirt&gender=0.25&height_cm=180.5&weight_kg=80"
                   "&untangle=false&untangler=reference&compression=meshopt&v=v1")  # fmt: skip
    query = parse_query(parse_qsl(urlsplit(url).query))
    assert query.request.spec() == spec and query.request.options.compression == "meshopt"
    assert query.version == "v1" and query.key_id is None and query.sig is None
    # Floats keep every digit: the id of the URL's request is the id of the POST's.
    odd = OutfitSpec(("tshirt",), 1 / 3, 170.123456789, 70.0)
    back = parse_query(parse_qsl(urlsplit(glb_url(odd, "none", "v1")).query)).request.spec()
    assert back.outfit_id("v1") == odd.outfit_id("v1")


def test_girths_round_trip_when_given_and_are_absent_otherwise():
    spec = OutfitSpec(("tshirt",), 1.0, 165.0, 60.0, chest_cm=88.5, waist_cm=70.125)
    url = glb_url(spec, "none", "v1")
    assert url == (
        "/v1/outfits.glb?garments=tshirt&gender=1&height_cm=165&weight_kg=60&chest_cm=88.5"
        "&waist_cm=70.125&v=v1"
    )
    back = parse_query(parse_qsl(urlsplit(url).query)).request.spec()
    assert back == spec and back.hip_cm is None
    # a girth given changes the outfit: another id, another URL
    assert back.outfit_id("v1") != OutfitSpec(("tshirt",), 1.0, 165.0, 60.0).outfit_id("v1")


def test_sizes_round_trip_and_a_size_is_another_outfit():
    spec = OutfitSpec(("pants", "tshirt"), 0.0, 180.0, 80.0, sizes=(None, "L"))
    url = glb_url(spec, "none", "v1")
    assert url == "/v1/outfits.glb?garments=pants,tshirt:L&gender=0&height_cm=180&weight_kg=80&v=v1"
    back = parse_query(parse_qsl(urlsplit(url).query)).request.spec()
    assert back == spec and back.size_of(1) == "L" and back.size_of(0) is None
    bare = OutfitSpec(("pants", "tshirt"), 0.0, 180.0, 80.0)
    # no size named is one outfit however it is said, and the ids of the outfits before sizes stay
    assert OutfitSpec(("pants", "tshirt"), 0.0, 180.0, 80.0, sizes=(None, None)) == bare
    assert "sizes" not in bare.canonical_json()
    assert back.outfit_id("v1") != bare.outfit_id("v1")
    assert spec.outfit_id("v1") != OutfitSpec(
        ("pants", "tshirt"), 0.0, 180.0, 80.0, sizes=(None, "M")
    ).outfit_id("v1")


def test_a_sized_post_and_its_url_are_one_outfit(app_and_engine):
    client, engine = app_and_engine
    posted = client.post("/v1/outfits", json={"garments": ["pants", {"id": "tshirt", "size": "S"}]}).json()
    assert "garments=pants,tshirt:S&" in posted["glb_url"]
    assert client.get(posted["glb_url"]).headers["x-outfit-id"] == posted["id"]
    assert engine["it"].calls == 1


def test_a_url_with_girths_makes_the_posts_outfit(app_and_engine):
    client, engine = app_and_engine
    request = {"garments": ["tshirt"], "body": {"gender": 1, "height_cm": 165, "weight_kg": 60, "hip_cm": 95}}
    posted = client.post("/v1/outfits", json=request).json()
    assert "&hip_cm=95&" in posted["glb_url"]
    assert posted["report"]["body"]["predicted"] == ["chest_cm", "waist_cm"]
    assert client.get(posted["glb_url"]).headers["x-outfit-id"] == posted["id"]
    assert engine["it"].calls == 1


def test_another_replica_makes_the_same_bytes(replicas):
    (one, e1), (two, e2) = replicas
    made = one.post("/v1/outfits", json=TINY).json()
    elsewhere = two.get(made["glb_url"])
    assert elsewhere.status_code == 200 and elsewhere.headers["content-type"] == GLB
    assert elsewhere.content == one.get(made["glb_url"]).content
    assert elsewhere.headers["etag"] == f'"{made["id"]}"' == elsewhere.headers["x-outfit-id"].join('""')
    assert elsewhere.headers["cache-control"] == IMMUTABLE
    assert e1["it"].calls == 1 and e2["it"].calls == 1  # each replica made it once, then cached it
    assert two.get(made["glb_url"]).content == elsewhere.content and e2["it"].calls == 1


def test_if_none_match_is_304_without_making_the_outfit(replicas):
    (one, _), (two, e2) = replicas
    made = one.post("/v1/outfits", json=TINY).json()
    tag = f'"{made["id"]}"'
    response = two.get(made["glb_url"], headers={"If-None-Match": f'"other", {tag}'})
    assert response.status_code == 304 and response.content == b""
    assert response.headers["etag"] == tag and response.headers["cache-control"] == IMMUTABLE
    assert e2["it"].calls == 0
    assert two.get(made["glb_url"], headers={"If-None-Match": '"other"'}).status_code == 200
    # A gzipping proxy weakens the tag (nginx: W/"..."), and a cache may ask for any version (*).
    for weak in (f"W/{tag}", "*"):
        assert two.get(made["glb_url"], headers={"If-None-Match": weak}).status_code == 304


def test_a_url_of_another_model_version_is_served_but_revalidated(client):
    made = client.post("/v1/outfits", json=TINY).json()
    for url in (made["glb_url"].replace("v=fake", "v=older"), made["glb_url"].replace("&v=fake", "")):
        response = client.get(url)
        assert response.status_code == 200 and response.headers["cache-control"] == "public, no-cache"
        assert response.headers["etag"] == f'"{made["id"]}"'


def test_measures_do_not_change_the_url_nor_make_the_outfit_again(app_and_engine):
    client, engine = app_and_engine
    measured = client.post("/v1/outfits", json=TINY | {"options": {"measure": True}}).json()
    plain = client.post("/v1/outfits", json=TINY).json()
    assert measured["glb_url"] == plain["glb_url"] and measured["id"] != plain["id"]
    assert client.get(measured["glb_url"]).status_code == 200 and engine["it"].calls == 1


def query_item(item) -> str | None:
    """A ``garments`` item as the URL spells it (``id`` or ``id:SIZE``), or None where it cannot."""
    if isinstance(item, str):
        return item
    strings = isinstance(item, dict) and all(isinstance(v, str) for v in item.values())
    if strings and set(item) == {"id", "size"}:
        return f"{item['id']}:{item['size']}"
    return None


def as_query(body) -> list[tuple[str, str]] | None:
    """A POST body as GLB URL parameters, or None where a query cannot say the same thing (a number
    given as text, a non-list of garments, a field the URL does not have)."""
    if not isinstance(body, dict) or set(body) - {"garments", "body", "options"}:
        return None
    items = []
    if "garments" in body:
        if not isinstance(body["garments"], list) or not all(map(query_item, body["garments"])):
            return None
        items.append(("garments", ",".join(map(query_item, body["garments"]))))
    for name, value in body.get("body", {}).items():
        if name not in ("gender", "height_cm", "weight_kg", *GIRTH_FIELDS) or type(value) not in (int, float):
            return None
        items.append((name, repr(value)))
    for name, value in body.get("options", {}).items():
        if name not in ("untangle", "include_body", "untangler") or type(value) is not str:
            return None
        items.append((name, value))
    return items


PARITY = [case for case in BAD_INPUT if as_query(case[0]) is not None]


def test_parity_table_covers_the_usual_mistakes():
    assert len(PARITY) >= 8


@pytest.mark.parametrize(("body", "field", "message", "allowed"), PARITY)
def test_bad_urls_get_the_posts_messages(client, body, field, message, allowed):
    response = client.get(f"/v1/outfits.glb?{urlencode(as_query(body), safe=',')}")
    assert response.status_code == 422, response.text
    assert {"field": field, "message": message, "allowed": allowed} in response.json()["errors"]


@pytest.mark.parametrize(
    ("query", "field", "message", "allowed"),
    [
        ("height_cm=180", "garments", "Field required", ALLOWED["garments"] + ": tshirt, pants"),
        ("garments=tshirt&height_cm=tall", "body.height_cm", "Input should be a valid number",
         ALLOWED["body.height_cm"]),
        ("garments=tshirt&untangle=1", "options.untangle", "Input should be a valid boolean",
         "true or false"),
        ("garments=tshirt&compression=zip", "options.compression",
         "Input should be 'none', 'quantized' or 'meshopt'", ALLOWED["options.compression"]),
        ("garments=tshirt&colour=red", "query.colour", "unknown field", ALLOWED["query"]),
        ("garments=tshirt&v=a&v=b", "query.v", "given more than once", "see openapi.yaml"),
        ("garments=tshirt&height_cm=170&height_cm=180", "query.height_cm", "given more than once",
         ALLOWED["query.height_cm"]),
        ("garments=tshirt&gender=nan", "body.gender", "Input should be a finite number",
         ALLOWED["body.gender"]),
        ("garments=tshirt&hip_cm=wide", "body.hip_cm", "Input should be a valid number",
         ALLOWED["body.hip_cm"]),
        ("garments=tshirt&waist_cm=inf", "body.waist_cm", "Input should be a finite number",
         ALLOWED["body.waist_cm"]),
        ("garments=tshirt&chest_cm=-3", "body.chest_cm", "Input should be greater than 0",
         ALLOWED["body.chest_cm"]),
    ],
)  # fmt: skip
def test_bad_urls_name_the_parameter(client, query, field, message, allowed):
    response = client.get(f"/v1/outfits.glb?{query}")
    assert response.status_code == 422, response.text
    assert {"field": field, "message": message, "allowed": allowed} in response.json()["errors"]


def test_json_is_gzipped_for_clients_that_ask_and_glbs_are_not(client):
    plain = client.get("/openapi.json", headers={"Accept-Encoding": "identity"})
    assert "content-encoding" not in plain.headers and len(plain.content) >= 1024
    # httpx decodes gzip itself: read the raw stream to see what was sent.
    with client.stream("GET", "/openapi.json", headers={"Accept-Encoding": "gzip"}) as zipped:
        raw = b"".join(zipped.iter_raw())
        assert zipped.headers["content-encoding"] == "gzip" and zipped.headers["vary"] == "Accept-Encoding"
        assert int(zipped.headers["content-length"]) == len(raw) < len(plain.content)
    assert json.loads(gzip.decompress(raw)) == plain.json()
    small = client.post("/v1/outfits", json=TINY, headers={"Accept-Encoding": "gzip"})
    assert len(small.content) < 1024 and "content-encoding" not in small.headers
    with client.stream("GET", small.json()["glb_url"], headers={"Accept-Encoding": "gzip"}) as glb:
        assert "content-encoding" not in glb.headers and b"".join(glb.iter_raw())[:4] == b"glTF"


def test_openapi_yaml_is_served_and_docs_need_no_cdn(client):
    from service.cli import render_openapi

    response = client.get("/openapi.yaml")
    assert response.status_code == 200 and response.headers["content-type"].startswith("application/yaml")
    assert response.text == render_openapi()
    assert client.get("/docs").status_code == 404 and client.get("/redoc").status_code == 404
