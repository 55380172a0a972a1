"""Probes, catalog, CORS, readiness and model integrity at start-up (fake engine, tiny catalog)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from service.cli import main
from service.pipeline.catalog import load_catalog
from service.process.paths import REPO_ROOT
from service.server.app import create_app
from service.server.runtime import ModelIntegrityError
from service.server.settings import Settings
from tests.service_tools import FakeEngine

TSHIRT = {
    "id": "tshirt",
    "name": "T-shirt",
    "category": "top",
    "layer_rank": 1,
    "vertices": 4,
    "faces": 2,
    "openings": ["neck", "waist"],
    "material": None,
    "origin": "bundled",
    "sizes": ["XS", "S", "M", "L", "XL", "XXL"],
}
PANTS = {
    "id": "pants",
    "name": "Pants",
    "category": "bottom",
    "layer_rank": 0,
    "vertices": 3,
    "faces": 1,
    "openings": ["waist"],
    "material": None,
    "origin": "bundled",
    "sizes": [],
}


def fake_settings(models_dir: Path, **overrides) -> Settings:
    values = dict(models_dir=models_dir, verify_models=False, configure_logging=False,
                  self_test_garments=["tshirt"], self_test_untangle=False)  # fmt: skip
    return Settings(**(values | overrides))


def fake_factory(settings: Settings) -> FakeEngine:
    return FakeEngine(load_catalog(settings.catalog_dir()))


@pytest.fixture
def client(fake_models_dir: Path):
    app = create_app(fake_settings(fake_models_dir), fake_factory)
    with TestClient(app) as c:
        assert app.state.tryon.wait_loaded(10)
        yield c


@pytest.fixture
def client_without_models(tmp_path: Path) -> TestClient:
    return TestClient(create_app(fake_settings(tmp_path / "missing")))


def test_healthz(client_without_models: TestClient):
    response = client_without_models.get("/healthz")
    assert response.status_code == 200
    assert response.json() == {"status": "ok"}


def test_readyz_when_loaded_and_self_tested(client: TestClient):
    response = client.get("/readyz")
    assert response.status_code == 200
    assert response.json() == {"ready": True, "garments": 2, "model_version": "fake"}
    assert "ulnef_ready 1.0" in client.get("/metrics").text


def test_readyz_before_start(client_without_models: TestClient):
    response = client_without_models.get("/readyz")
    assert response.status_code == 503
    assert response.json() == {"ready": False, "detail": "models not loaded yet"}


def test_readyz_false_when_models_fail_to_load(tmp_path: Path):
    app = create_app(fake_settings(tmp_path / "missing"), fake_factory)
    with TestClient(app) as c:
        assert not app.state.tryon.wait_loaded(10)
        response = c.get("/readyz")
        assert response.status_code == 503
        assert response.json()["detail"].startswith("start-up failed: FileNotFoundError")
        outfit = c.post("/v1/outfits", json={"garments": ["tshirt"]})
        assert outfit.status_code == 503
        assert outfit.headers["retry-after"] == "5"
        assert outfit.json()["detail"].startswith("not ready: start-up failed")


def test_readyz_false_when_self_test_fails(fake_models_dir: Path):
    settings = fake_settings(fake_models_dir, self_test_garments=["cape"])
    app = create_app(settings, fake_factory)
    with TestClient(app) as c:
        assert not app.state.tryon.wait_loaded(10)
        response = c.get("/readyz")
        assert response.status_code == 503
        assert response.json()["ready"] is False
        assert "start-up failed" in response.json()["detail"]


def test_garments_lists_catalog_in_order(client: TestClient):
    response = client.get("/v1/garments")
    assert response.status_code == 200
    assert response.json() == {"garments": [TSHIRT, PANTS]}


def test_garments_when_catalog_missing(client_without_models: TestClient):
    response = client_without_models.get("/v1/garments")
    assert response.status_code == 503
    assert response.json() == {"detail": "garment catalog not loaded"}


def test_cors_only_when_configured(fake_models_dir: Path):
    headers = {"Origin": "https://shop.example"}
    closed = TestClient(create_app(fake_settings(fake_models_dir)))
    assert "access-control-allow-origin" not in closed.get("/healthz", headers=headers).headers
    open_ = TestClient(create_app(fake_settings(fake_models_dir, cors_origins=["https://shop.example"])))
    response = open_.get("/healthz", headers=headers)
    assert response.headers["access-control-allow-origin"] == "https://shop.example"
    other = open_.get("/healthz", headers={"Origin": "https://evil.example"})
    assert "access-control-allow-origin" not in other.headers
    preflight = open_.options("/v1/outfits", headers={**headers, "Access-Control-Request-Method": "POST"})
    assert preflight.status_code == 200


def test_page_and_its_scripts_are_served(client: TestClient):
    page = client.get("/")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    for src in ("/static/vendor/model-viewer.min.js", "/static/page.js", "/static/page.css",
                "/static/favicon.svg"):  # fmt: skip
        assert src in page.text
        assert client.get(src).status_code == 200
    assert "https://" not in page.text  # nothing from a CDN


def test_favicon_ico_is_no_404(client: TestClient):
    response = client.get("/favicon.ico")
    assert response.status_code == 204 and response.content == b""


# ---------------------------------------------------------------- model integrity


@pytest.fixture
def models_copy(tmp_path: Path) -> Path:
    """A copy of the committed models (6-7 MB) that a test may damage."""
    target = tmp_path / "models"
    shutil.copytree(REPO_ROOT / "models", target)
    return target


def _start(models_dir: Path):
    app = create_app(fake_settings(models_dir, verify_models=True), fake_factory)
    with TestClient(app):
        pass


def test_start_refuses_a_missing_model_file(models_copy: Path):
    (models_copy / "untangler" / "values.onnx").unlink()
    with pytest.raises(ModelIntegrityError, match=r"(?s)refusing to start.*untangler/values.onnx: missing"):
        _start(models_copy)


def test_start_refuses_a_changed_model_file(models_copy: Path):
    path = models_copy / "fields" / "tshirt.onnx"
    data = bytearray(path.read_bytes())
    data[-1] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(ModelIntegrityError, match=r"fields/tshirt.onnx: sha256 mismatch"):
        _start(models_copy)


def test_start_accepts_intact_models(models_copy: Path):
    app = create_app(fake_settings(models_copy, verify_models=True), fake_factory)
    with TestClient(app) as client:  # started: every file checked against the manifest
        assert app.state.tryon.wait_loaded(10)
        assert client.get("/readyz").status_code == 200


def test_serve_command_refuses_damaged_models(models_copy: Path, monkeypatch, capsys):
    (models_copy / "garments" / "catalog.json").write_text("{}")
    monkeypatch.setenv("ULNEF_MODELS_DIR", str(models_copy))
    assert main(["serve", "--port", "1"]) == 1
    err = capsys.readouterr().err
    assert "ulnef serve: refusing to start" in err
    assert "garments/catalog.json: size mismatch" in err
