from __future__ import annotations

import json
from pathlib import Path

import pytest
import uvicorn
from fastapi import FastAPI

from service.cli import main
from service.process.paths import REPO_ROOT

TABLE = """\
id      name     category  layer rank  vertices  faces  openings
tshirt  T-shirt  top       1           4         2      neck, waist
pants   Pants    bottom    0           3         1      waist
"""


@pytest.fixture
def models_env(monkeypatch: pytest.MonkeyPatch, fake_models_dir: Path) -> Path:
    monkeypatch.setenv("ULNEF_MODELS_DIR", str(fake_models_dir))
    return fake_models_dir


def test_garments_table(models_env: Path, capsys: pytest.CaptureFixture[str]):
    assert main(["garments"]) == 0
    assert capsys.readouterr().out == TABLE


def test_garments_json_matches_http_body(models_env: Path, capsys: pytest.CaptureFixture[str]):
    assert main(["garments", "--json"]) == 0
    body = json.loads(capsys.readouterr().out)
    assert [g["id"] for g in body["garments"]] == ["tshirt", "pants"]
    assert body["garments"][0] == {
        "id": "tshirt",
        "name": "T-shirt",
        "category": "top",
        "layer_rank": 1,
        "vertices": 4,
        "faces": 2,
        "openings": ["neck", "waist"],
        "material": None,
        "origin": "bundled",
    }


def test_garments_without_catalog_fails_with_message(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
):
    monkeypatch.setenv("ULNEF_MODELS_DIR", str(tmp_path / "missing"))
    assert main(["garments"]) == 1
    assert "garment catalog not loaded" in capsys.readouterr().err


def test_openapi_writes_committed_file(tmp_path: Path):
    out = tmp_path / "openapi.yaml"
    assert main(["openapi", "-o", str(out)]) == 0
    assert out.read_text() == (REPO_ROOT / "openapi.yaml").read_text()


def test_serve_runs_uvicorn_on_requested_address(monkeypatch: pytest.MonkeyPatch):
    calls = []
    monkeypatch.setattr(uvicorn, "run", lambda app, **kwargs: calls.append((app, kwargs)))
    assert main(["serve", "--host", "0.0.0.0", "--port", "9001"]) == 0
    [(app, kwargs)] = calls
    assert isinstance(app, FastAPI)
    assert kwargs == {"host": "0.0.0.0", "port": 9001, "log_level": "info", "log_config": None,
                      "limit_concurrency": 1000, "timeout_graceful_shutdown": 20}  # fmt: skip
