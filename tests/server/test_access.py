"""API keys, signed GLB URLs, per-key rate limits and the metrics token (``service.server.access``)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from service.server.access import KeysFileError, RateLimiter, read_digests
from tests.server.apps import make_app
from tests.server.test_api_outfits import TINY

KEY, OTHER = "shop-key-1f8e2d", "shop-key-77aa01"
NO_KEY = "missing or unknown API key: send `Authorization: Bearer <key>` (ask the operator for a key)"


def digest(key: str) -> str:
    return hashlib.sha256(key.encode()).hexdigest()


def keys_file(tmp_path: Path, *keys: str) -> Path:
    path = tmp_path / "keys.txt"
    path.write_text("# sha256 of each key\n\n" + "\n".join(f"{digest(k)}  # {i}" for i, k in enumerate(keys)))
    return path


@pytest.fixture
def keyed(fake_models_dir: Path, tmp_path: Path):
    """An app with two keys, signed URLs, 3 requests of burst and a slow refill, and a metrics token."""
    secret = tmp_path / "url-secret"
    secret.write_text("0123456789abcdef0123456789abcdef\n")
    app, _ = make_app(fake_models_dir, api_keys_file=keys_file(tmp_path, KEY, OTHER), url_secret_file=secret,
                      rate_limit_burst=3, rate_limit_per_minute=0.5, metrics_token="scrape-me")  # fmt: skip
    with TestClient(app) as client:
        assert app.state.tryon.wait_loaded(10)
        yield client


def bearer(key: str) -> dict:
    return {"Authorization": f"Bearer {key}"}


def test_outfit_endpoints_need_a_key(keyed: TestClient):
    for response in (keyed.post("/v1/outfits", json=TINY),
                     keyed.post("/v1/outfits", json=TINY, headers=bearer("guess")),
                     keyed.get("/v1/outfits.glb?garments=tshirt"),
                     keyed.get("/v1/outfits/" + "0" * 32 + ".glb")):  # fmt: skip
        assert response.status_code == 401 and response.json() == {"detail": NO_KEY}
        assert response.headers["www-authenticate"] == "Bearer"
    assert keyed.post("/v1/outfits", json=TINY, headers=bearer(KEY)).status_code == 200
    # Probes, the garment list and the page stay open.
    assert keyed.get("/readyz").status_code == 200 and keyed.get("/v1/garments").status_code == 200


def test_signed_glb_url_needs_no_header_and_cannot_be_altered(keyed: TestClient):
    url = keyed.post("/v1/outfits", json=TINY, headers=bearer(KEY)).json()["glb_url"]
    assert f"&k={digest(KEY)[:12]}&sig=" in url
    assert keyed.get(url).status_code == 200
    kid, other = digest(KEY)[:12], digest(OTHER)[:12]
    for altered in (url.replace("height_cm=180", "height_cm=181"), url.replace("pants,tshirt", "pants"),
                    url.replace(f"k={kid}", f"k={other}"), url[:-1] + "0"):  # fmt: skip
        assert altered != url and keyed.get(altered).status_code == 401


def test_without_a_url_secret_the_glb_url_needs_the_key(fake_models_dir: Path, tmp_path: Path):
    app, _ = make_app(fake_models_dir, api_keys_file=keys_file(tmp_path, KEY))
    with TestClient(app) as client:
        assert app.state.tryon.wait_loaded(10)
        url = client.post("/v1/outfits", json=TINY, headers=bearer(KEY)).json()["glb_url"]
        assert "sig=" not in url and client.get(url).status_code == 401
        assert client.get(url, headers=bearer(KEY)).status_code == 200


def test_rate_limit_is_per_key_with_retry_after(keyed: TestClient):
    answers = [keyed.post("/v1/outfits", json=TINY, headers=bearer(KEY)) for _ in range(4)]
    assert [a.status_code for a in answers] == [200, 200, 200, 429]
    assert 118 <= int(answers[-1].headers["retry-after"]) <= 120  # one token at 0.5 a minute
    detail = f"rate limit of key {digest(KEY)[:12]}: 0.5 outfit requests a minute"
    assert answers[-1].json()["detail"] == detail
    assert keyed.post("/v1/outfits", json=TINY, headers=bearer(OTHER)).status_code == 200
    metrics = keyed.get("/metrics", headers=bearer("scrape-me")).text
    assert 'ulnef_outfit_rejected_total{reason="rate_limit"} 1.0' in metrics


def test_token_bucket_refills_at_its_rate():
    now = [0.0]
    limiter = RateLimiter(rate_per_minute=60, burst=2, clock=lambda: now[0])
    assert limiter.take("a") is None and limiter.take("a") is None
    assert limiter.take("a") == 1.0
    now[0] = 0.5
    assert limiter.take("a") == 1.0  # half a token back: still a whole second to wait, rounded up
    now[0] = 1.0
    assert limiter.take("a") is None and limiter.take("a") == 1.0
    now[0] = 100.0  # refills only up to the burst
    assert [limiter.take("a") for _ in range(3)] == [None, None, 1.0]


def test_metrics_behind_their_token(keyed: TestClient):
    assert keyed.get("/metrics").status_code == 401
    assert keyed.get("/metrics", headers=bearer(KEY)).status_code == 401
    assert keyed.get("/metrics", headers=bearer("scrape-me")).status_code == 200


def test_keys_file_must_hold_digests_only(tmp_path: Path):
    bad = tmp_path / "bad.txt"
    bad.write_text(f"{digest(KEY)}\nmy-plain-key\n")
    with pytest.raises(KeysFileError, match="line 2: not a sha256 hex digest"):
        read_digests(bad)
    (tmp_path / "empty.txt").write_text("# nothing\n")
    with pytest.raises(KeysFileError, match="no key digests"):
        read_digests(tmp_path / "empty.txt")
    with pytest.raises(KeysFileError, match="missing.txt"):
        read_digests(tmp_path / "missing.txt")
    assert read_digests(keys_file(tmp_path, KEY, OTHER)) == {digest(KEY), digest(OTHER)}


def test_serve_refuses_to_start_on_a_broken_keys_file(tmp_path: Path, monkeypatch, capsys):
    from service.cli import main

    (tmp_path / "keys.txt").write_text("")  # the Kubernetes Secret as shipped, before it is filled
    monkeypatch.setenv("ULNEF_API_KEYS_FILE", str(tmp_path / "keys.txt"))
    monkeypatch.setenv("ULNEF_VERIFY_MODELS", "false")
    assert main(["serve", "--port", "1"]) == 1
    assert "ulnef serve: API keys file" in capsys.readouterr().err
