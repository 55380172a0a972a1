"""POST /v1/admin/reload (fake engine, tiny catalog): disabled without a token, 401 on a wrong one,
the new engine served after a reload (with what it added), a failed reload keeping the old one, and
one reload at a time."""

from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from service.pipeline.catalog import load_catalog
from service.server.app import create_app
from service.server.routes.admin import BAD_TOKEN, DISABLED
from service.server.settings import Settings
from tests.service_tools import FakeEngine

TOKEN = "s3cret-token"


class Factory:
    """Engines over the tiny catalog; the second and later ones also serve a third garment, or fail."""

    def __init__(self, fail_after: int | None = None):
        self.calls = 0
        self.fail_after = fail_after

    def __call__(self, settings: Settings) -> FakeEngine:
        self.calls += 1
        if self.fail_after is not None and self.calls > self.fail_after:
            raise RuntimeError("the new models are broken")
        catalog = dict(load_catalog(settings.catalog_dir()))
        if self.calls > 1:
            catalog["new_skirt"] = catalog["pants"]
        engine = FakeEngine(catalog)
        engine.model_version = f"fake{self.calls}"
        return engine


def _client(models_dir: Path, factory, token: str | None = TOKEN) -> TestClient:
    settings = Settings(
        models_dir=models_dir, verify_models=False, configure_logging=False, admin_token=token,
        self_test_garments=["tshirt"], self_test_untangle=False,
    )  # fmt: skip
    return TestClient(create_app(settings, factory))


def test_disabled_without_a_token(fake_models_dir: Path):
    with _client(fake_models_dir, Factory(), token=None) as client:
        response = client.post("/v1/admin/reload", headers={"Authorization": f"Bearer {TOKEN}"})
    assert response.status_code == 404 and response.json()["detail"] == DISABLED


@pytest.mark.parametrize("header", [None, "Bearer wrong", TOKEN, f"bearer {TOKEN}"])
def test_a_missing_or_wrong_token_is_refused(fake_models_dir: Path, header):
    factory = Factory()
    with _client(fake_models_dir, factory) as client:
        client.app.state.tryon.wait_loaded(10)
        headers = {} if header is None else {"Authorization": header}
        response = client.post("/v1/admin/reload", headers=headers)
    assert response.status_code == 401 and response.json()["detail"] == BAD_TOKEN
    assert factory.calls == 1  # nothing was reloaded


def test_a_reload_serves_the_new_models(fake_models_dir: Path):
    with _client(fake_models_dir, Factory()) as client:
        assert client.app.state.tryon.wait_loaded(10)
        assert client.get("/readyz").json()["garments"] == 2
        response = client.post("/v1/admin/reload", headers={"Authorization": f"Bearer {TOKEN}"})
        assert response.status_code == 200, response.text
        assert response.json() == {"model_version": "fake2", "garments": 3, "added": ["new_skirt"],
                                   "removed": [], "left_out": []}  # fmt: skip
        assert client.get("/readyz").json() == {"ready": True, "garments": 3, "model_version": "fake2"}
        outfit = client.post("/v1/outfits", json={"garments": ["new_skirt"], "options": {"untangle": False}})
        assert outfit.status_code == 200, outfit.text


def test_a_failed_reload_keeps_serving_the_old_models(fake_models_dir: Path):
    with _client(fake_models_dir, Factory(fail_after=1)) as client:
        assert client.app.state.tryon.wait_loaded(10)
        response = client.post("/v1/admin/reload", headers={"Authorization": f"Bearer {TOKEN}"})
        assert response.status_code == 503
        assert response.json()["detail"] == "reload failed: RuntimeError: the new models are broken"
        assert client.get("/readyz").json() == {"ready": True, "garments": 2, "model_version": "fake1"}


def test_one_reload_at_a_time(fake_models_dir: Path):
    with _client(fake_models_dir, Factory()) as client:
        tryon = client.app.state.tryon
        assert tryon.wait_loaded(10)
        with tryon._reloading:  # as if another reload were running
            response = client.post("/v1/admin/reload", headers={"Authorization": f"Bearer {TOKEN}"})
        assert response.status_code == 409 and response.json()["detail"] == "a reload is already running"
