"""The HTTP contract of docs/design.md section 6 on the committed models, and the engine's numerical
fallbacks. Outfits here skip untangling (``options.untangle=false``): the pipeline has its own tests,
these are about what the service does with it."""

from __future__ import annotations

import io

import numpy as np
import pytest
import trimesh
from fastapi.testclient import TestClient

import service.pipeline.outfit
from service.pipeline.tryon import OutfitSpec, finite_layers
from service.server.app import create_app
from service.server.settings import Settings

pytest.importorskip("onnxruntime")
FAST = {"untangle": False}
GLB = "model/gltf-binary"


@pytest.fixture(scope="module")
def app():
    app = create_app(Settings(self_test_untangle=False, configure_logging=False))
    with TestClient(app) as client:
        assert app.state.tryon.wait_loaded(120), app.state.tryon.detail
        app.state.client = client
        yield app


@pytest.fixture
def client(app) -> TestClient:
    return app.state.client


def scene_of(data: bytes) -> trimesh.Scene:
    return trimesh.load(io.BytesIO(data), file_type="glb", process=False)


def test_ready_after_the_self_test(client: TestClient):
    body = client.get("/readyz").json()
    assert body["ready"] is True and body["garments"] == 7 and len(body["model_version"]) == 12


def test_outfit_json_then_glb_url(client: TestClient):
    request = {"garments": ["shorts", "tshirt"], "body": {"gender": 0.0, "height_cm": 180, "weight_kg": 80},
               "options": FAST}  # fmt: skip
    response = client.post("/v1/outfits", json=request)
    assert response.status_code == 200, response.text
    answer = response.json()
    assert answer["report"]["garments"] == ["shorts", "tshirt"]
    assert answer["report"]["numerical_fallback"] == []
    assert set(answer["report"]["seconds"]) >= {"body", "explicit", "world", "total"}
    glb = client.get(answer["glb_url"])
    assert glb.status_code == 200 and glb.headers["content-type"] == GLB
    scene = scene_of(glb.content)
    # One named node, mesh and material per layer, body included; metres, Y up.
    assert sorted(scene.graph.nodes_geometry) == ["body", "shorts", "tshirt"]
    materials = {name: g.visual.material.name for name, g in scene.geometry.items()}
    assert materials == {"body": "body", "shorts": "shorts", "tshirt": "tshirt"}
    body = scene.geometry["body"].vertices
    assert body[:, 1].max() - body[:, 1].min() == pytest.approx(1.80, abs=1e-4)
    assert all(np.isfinite(g.vertices).all() for g in scene.geometry.values())


def test_outfit_glb_directly_without_body(client: TestClient):
    request = {"garments": ["shorts"], "options": FAST | {"include_body": False}}
    response = client.post("/v1/outfits", json=request, headers={"Accept": GLB})
    assert response.status_code == 200 and response.headers["content-type"] == GLB
    assert sorted(scene_of(response.content).graph.nodes_geometry) == ["shorts"]


def test_body_out_of_the_models_range_names_the_field(client: TestClient):
    """A hip no adult of that height and weight has: the range comes from the girth priors."""
    from service.pipeline.body import format_range
    from service.pipeline.girth_priors import GirthPriors

    body = {"gender": 1, "height_cm": 165, "weight_kg": 60, "hip_cm": 300}
    request = {"garments": ["shorts"], "body": body}
    response = client.post("/v1/outfits", json=request)
    assert response.status_code == 422
    allowed = format_range(*GirthPriors.load().possible_range(1.0, "hip_cm", 165.0, 60.0))
    assert response.json()["errors"] == [{
        "field": "body.hip_cm",
        "message": f"hip_cm=300 is outside the range {allowed} cm that adults of height_cm=165 and "
                   "weight_kg=60 have",
        "allowed": allowed,
    }]  # fmt: skip


def test_weight_range_depends_on_height(client: TestClient):
    """BMI 13-70 at that height: 29.3-157.5 kg at 150 cm."""
    request = {"garments": ["shorts"], "body": {"gender": 0, "height_cm": 150, "weight_kg": 160}}
    (error,) = client.post("/v1/outfits", json=request).json()["errors"]
    assert error["field"] == "body.weight_kg" and error["allowed"] == "29.3-157.5"


def test_metrics_have_stage_histograms(client: TestClient):
    client.post("/v1/outfits", json={"garments": ["shorts"], "options": FAST})
    text = client.get("/metrics").text
    for stage in ("body", "explicit", "world", "total"):
        assert f'ulnef_outfit_stage_seconds_count{{stage="{stage}"}}' in text


# ---------------------------------------------------------------- numerical faults


def test_finite_layers_replaces_and_drops():
    good, bad = np.zeros((3, 3)), np.full((3, 3), np.nan)
    faces = np.array([[0, 1, 2]])
    layers, flagged = finite_layers([("a", good, faces), ("b", bad, faces), ("c", bad, faces)],
                                    {"b": good, "c": bad})  # fmt: skip
    assert [g for g, _, _ in layers] == ["a", "b"] and flagged == ["b", "c"]
    assert np.isfinite(layers[1][1]).all()


def test_nan_from_the_fit_falls_back_to_the_explicit_mesh(app, monkeypatch):
    real = service.pipeline.outfit.make_outfit

    def nan_fit(models, ids, beta, untangle_layers=True, *args, **kwargs):
        outfit = real(models, ids, beta, False, *args, **kwargs)
        if untangle_layers:
            gid, v, f = outfit.garments[0]
            outfit.garments[0] = (gid, np.full_like(v, np.nan), f)
        return outfit

    monkeypatch.setattr(service.pipeline.outfit, "make_outfit", nan_fit)
    result = app.state.tryon.engine.make(OutfitSpec(("shorts",), untangle=True))
    assert result.report["numerical_fallback"] == ["shorts"]
    scene = scene_of(result.glb)
    assert all(np.isfinite(g.vertices).all() for g in scene.geometry.values())
    assert sorted(scene.graph.nodes_geometry) == ["body", "shorts"]


def test_failing_untangling_falls_back_and_is_flagged(app, monkeypatch):
    real = service.pipeline.outfit.make_outfit

    def failing(models, ids, beta, untangle_layers=True, *args, **kwargs):
        if untangle_layers:
            raise np.linalg.LinAlgError("L-BFGS went wrong")
        return real(models, ids, beta, False, *args, **kwargs)

    monkeypatch.setattr(service.pipeline.outfit, "make_outfit", failing)
    result = app.state.tryon.engine.make(OutfitSpec(("shorts",), untangle=True))
    assert result.report["numerical_fallback"] == ["shorts"] and result.glb[:4] == b"glTF"


def test_every_garment_node_is_textured_and_the_catalog_says_how(client: TestClient):
    """Each garment in the GLB has TEXCOORD_0 from its display mesh and its material's PNG textures,
    embedded; ``GET /v1/garments`` names the material's texture files."""
    import json
    import struct

    from service.pipeline.catalog import load_catalog

    catalog = load_catalog()
    listed = {g["id"]: g["material"] for g in client.get("/v1/garments").json()["garments"]}
    assert listed == {gid: g.material.summary() for gid, g in catalog.items()}
    assert all(m["textures"] == {"base_color": f"{gid}.base.png", "normal": f"{gid}.normal.png"}
               for gid, m in listed.items())  # fmt: skip
    request = {"garments": ["pants", "tshirt"], "options": FAST}
    data = client.post("/v1/outfits", json=request, headers={"Accept": GLB}).content
    (n,) = struct.unpack("<I", data[12:16])
    doc = json.loads(data[20 : 20 + n])
    binary = data[20 + n + 8 :]
    meshes = {m["name"]: m["primitives"][0] for m in doc["meshes"]}
    assert "TEXCOORD_0" not in meshes["body"]["attributes"]
    for gid in ("pants", "tshirt"):
        primitive, display = meshes[gid], catalog[gid].display
        assert doc["accessors"][primitive["attributes"]["TEXCOORD_0"]]["count"] == len(display.uv)
        material = doc["materials"][primitive["material"]]
        texture = doc["textures"][material["pbrMetallicRoughness"]["baseColorTexture"]["index"]]
        image = doc["images"][texture["source"]]
        view = doc["bufferViews"][image["bufferView"]]
        png = binary[view["byteOffset"] : view["byteOffset"] + view["byteLength"]]
        assert png == catalog[gid].material.textures["base_color"]
