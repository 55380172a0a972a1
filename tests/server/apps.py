"""Apps over the fake engine (``tests.service_tools.FakeEngine``) for the HTTP tests."""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI

from service.pipeline.catalog import load_catalog
from service.server.app import create_app
from service.server.settings import Settings
from tests.service_tools import FakeEngine


def make_app(
    models_dir: Path, delay: float = 0.0, crossings: int = 0, **overrides
) -> tuple[FastAPI, dict]:
    """The app over a fake engine with ``overrides`` of its settings; ``engine["it"]`` once started."""
    values = dict(models_dir=models_dir, verify_models=False, configure_logging=False,
                  self_test_garments=[], self_test_untangle=False)  # fmt: skip
    engine = {}

    def factory(settings: Settings) -> FakeEngine:
        engine["it"] = FakeEngine(load_catalog(settings.catalog_dir()), delay=delay, crossings=crossings)
        return engine["it"]

    app = create_app(Settings(**(values | overrides)), factory)
    return app, engine
