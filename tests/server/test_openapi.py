"""The committed ``openapi.yaml`` is the app's schema.

Refresh after changing the API:  ``.venv/bin/ulnef openapi -o openapi.yaml``
"""

from __future__ import annotations

import yaml

from service.cli import render_openapi
from service.process.paths import REPO_ROOT
from service.server.app import create_app

COMMITTED = REPO_ROOT / "openapi.yaml"


def test_committed_openapi_matches_app():
    assert COMMITTED.read_text() == render_openapi(), "stale: run `ulnef openapi -o openapi.yaml`"


def test_committed_openapi_parses_to_app_schema():
    assert yaml.safe_load(COMMITTED.read_text()) == create_app().openapi()
