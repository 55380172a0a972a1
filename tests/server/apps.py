"""Apps over the fake engine (``tests.service_tools.FakeEngine``) for the HTTP tests."""

from __future__ import annotations

import threading
from pathlib import Path

from fastapi import FastAPI

from service.pipeline.catalog import load_catalog
from service.server.app import create_app
from service.server.settings import Settings
from tests.service_tools import FakeEngine


class RangedFakeEngine(FakeEngine):
    """The fake engine with the ranges its ``validate`` keeps (no body above 200 cm for gender > 0.5)."""

    def body_ranges(self, gender: float, height_cm: float | None) -> dict:
        heights = (140.0, 200.0 if gender > 0.5 else 210.0)
        h = sum(heights) / 2 if height_cm is None else min(max(height_cm, heights[0]), heights[1])
        return {"height_cm": heights, "weight_kg": (h - 120.0, h - 80.0), "at_height_cm": h}


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
        engine["it"] = RangedFakeEngine(catalog, delay=delay, crossings=crossings, release=release)
        return engine["it"]

    app = create_app(Settings(**(values | overrides)), factory)
    return app, engine
