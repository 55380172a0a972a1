from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.settings import Settings

TSHIRT = {
    "id": "tshirt",
    "name": "T-shirt",
    "category": "top",
    "layer_rank": 1,
    "vertices": 4,
    "faces": 2,
    "openings": ["neck", "waist"],
}
PANTS = {
    "id": "pants",
    "name": "Pants",
    "category": "bottom",
    "layer_rank": 0,
    "vertices": 3,
    "faces": 1,
    "openings": ["waist"],
}


@pytest.fixture
def client(fake_models_dir: Path) -> TestClient:
    return TestClient(create_app(Settings(models_dir=fake_models_dir)))


@pytest.fixture
def client_without_models(tmp_path: Path) -> TestClient:
    return TestClient(create_app(Settings(models_dir=tmp_path / "missing")))


def test_healthz(client_without_models: TestClient):
    response = client_without_models.get("/healthz")
    assert response.status_code == 200
    assert response.json() == {"status": "ok"}


def test_readyz_when_catalog_loads(client: TestClient):
    response = client.get("/readyz")
    assert response.status_code == 200
    assert response.json() == {"ready": True, "garments": 2}


def test_readyz_when_catalog_missing(client_without_models: TestClient):
    response = client_without_models.get("/readyz")
    assert response.status_code == 503
    assert response.json() == {"ready": False, "detail": "garment catalog not loaded"}


def test_readyz_recovers_once_catalog_appears(tmp_path: Path, fake_models_dir: Path):
    late = tmp_path / "late"
    client = TestClient(create_app(Settings(models_dir=late)))
    assert client.get("/readyz").status_code == 503
    fake_models_dir.rename(late)
    assert client.get("/readyz").json() == {"ready": True, "garments": 2}


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
    closed = TestClient(create_app(Settings(models_dir=fake_models_dir)))
    assert "access-control-allow-origin" not in closed.get("/healthz", headers=headers).headers
    open_ = TestClient(
        create_app(Settings(models_dir=fake_models_dir, cors_origins=["https://shop.example"]))
    )
    response = open_.get("/healthz", headers=headers)
    assert response.headers["access-control-allow-origin"] == "https://shop.example"
