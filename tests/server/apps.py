"""Apps over the fake engine (``tests.service_tools.FakeEngine``) for the HTTP tests."""

from __future__ import annotations

import threading
from functools import cache
from pathlib import Path

from fastapi import FastAPI

from service.pipeline.catalog import load_catalog
from service.pipeline.tryon import ModelEngine
from service.server.app import create_app
from service.server.settings import Settings
from tests.service_tools import FakeEngine


def make_app(
    models_dir: Path, delay: float = 0.0, crossings: int = 0, release: threading.Event | None = None,
    **overrides,
) -> tuple[FastAPI, dict]:
    """The app over a fake engine with ``overrides`` of its settings; ``engine["it"]`` once started.
    ``release``: every outfit waits for this event (``FakeEngine``)."""
    values = dict(models_dir=models_dir, verify_models=False, configure_logging=False,
                  self_test_garments=[], self_test_untangle=False)  # fmt: skip
    engine = {}

    def factory(settings: Settings) -> FakeEngine:
        catalog = load_catalog(settings.catalog_dir())
        engine["it"] = FakeEngine(catalog, delay=delay, crossings=crossings, release=release)
        return engine["it"]

    app = create_app(Settings(**(values | overrides)), factory)
    return app, engine


@cache
def body_engine() -> ModelEngine:
    """A ``ModelEngine`` over the committed body model and girth priors only (no garments, loads in
    ~0.3 s): its ``make_body``, ``body`` and ``body_ranges`` are the real ones."""
    from service.pipeline.body import BodyModel
    from service.pipeline.body_build import BodyBuilder
    from service.pipeline.girth_priors import GirthPriors

    body = BodyModel.load()
    models = type("BodyOnlyModels", (), {"body": body, "bodies": BodyBuilder(body, GirthPriors.load())})()
    return ModelEngine(models, "bodies")
