"""A full house is refused at once: the request holding the last place is still being validated
(blocked here on an event), and the next request is answered 503 without waiting for it."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from fastapi.testclient import TestClient

from tests.server.apps import make_app

TINY = {"garments": ["pants", "tshirt"], "body": {"height_cm": 180}}
OTHER = {"garments": ["pants", "tshirt"], "body": {"height_cm": 181}}
WATCHDOG_S = 20  # only ends a test that failed (a request the loop never answered)


def test_a_full_house_is_refused_while_the_request_in_it_is_still_validated(fake_models_dir: Path):
    app, engine = make_app(fake_models_dir, workers=1, queue_size=0)
    with TestClient(app) as client:
        assert app.state.tryon.wait_loaded(10)
        fake = engine["it"]
        entered, release = threading.Event(), threading.Event()
        ended_by_the_test = []  # one entry per validation: whether the test (not the watchdog) ended it
        validate = fake.validate

        def held_validate(spec):
            entered.set()
            ended_by_the_test.append(release.wait(WATCHDOG_S))
            validate(spec)

        fake.validate = held_validate
        with ThreadPoolExecutor(1) as pool:
            first = pool.submit(client.post, "/v1/outfits", json=TINY)
            assert entered.wait(WATCHDOG_S)
            refused = client.post("/v1/outfits", json=OTHER)
            release.set()
            assert first.result(WATCHDOG_S).status_code == 200
        assert refused.status_code == 503 and refused.headers["retry-after"] == "1"
        assert refused.json() == {"detail": "overloaded: 1 outfits in progress, at capacity"}
        # The refused request was answered while the first one's validation was still held, and was
        # never validated itself (the place is taken before validation, which runs off the event loop).
        assert ended_by_the_test == [True]
        assert app.state.tryon.worker.pending == 0


def test_a_refused_validation_gives_its_place_back(app_and_engine):
    client, _ = app_and_engine
    for _ in range(12):  # more than the 1 + 8 places: none is kept by a refused request
        response = client.post("/v1/outfits", json={"garments": ["cape"]})
        assert response.status_code == 422
    assert client.app.state.tryon.worker.pending == 0
    assert client.post("/v1/outfits", json=TINY).status_code == 200
