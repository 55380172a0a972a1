"""Fixtures of the HTTP tests: a started app over the fake engine."""

from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from tests.server.apps import make_app


@pytest.fixture
def app_and_engine(fake_models_dir: Path):
    app, engine = make_app(fake_models_dir)
    with TestClient(app) as client:
        assert app.state.tryon.wait_loaded(10)
        yield client, engine


@pytest.fixture
def client(app_and_engine) -> TestClient:
    return app_and_engine[0]
