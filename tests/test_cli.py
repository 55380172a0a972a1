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


# ---------------------------------------------------------------- bad input: exit 2 and a message naming it


@pytest.fixture
def no_model_loading(monkeypatch: pytest.MonkeyPatch):
    """Bad input is refused before the models load (seconds): loading them fails the test."""
    from service.pipeline.outfit import OutfitModels

    def refuse(*args, **kwargs):
        raise AssertionError("the models were loaded for input that could be refused without them")

    monkeypatch.setattr(OutfitModels, "load", refuse)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--garments", ","], "--garments: give 1-4 comma-separated garment ids (`ulnef garments` lists "
         "them)"),
        (["--garments", "TShirt"], "--garments: 'TShirt' is no garment id (ids are 1-32 lower case letters, "
         "digits and _, starting with a letter)"),
        (["--garments", "cape"], "--garments: unknown id(s) ['cape']; allowed: "),
        (["--garments", "tshirt,tshirt"], "--garments: each id at most once, got ['tshirt', 'tshirt']"),
        (["--garments", "tshirt", "-o", "/nonexistent-dir/x.glb"], "-o /nonexistent-dir/x.glb: no such "
         "directory /nonexistent-dir"),
        (["--garments", "tshirt", "--gender", "1", "--height-cm", "135.6"], "--height-cm: height_cm=135.6 is "
         "outside the supported range 135.7-200.8 cm for gender=1"),
        (["--garments", "tshirt", "--gender", "2"], "--gender: gender=2 is outside the supported range 0-1 "
         "(0 male, 1 female)"),
        (["--garments", "tshirt", "--weight-kg", "nan"], "--weight-kg: weight_kg=nan is not a finite number"),
    ],
)  # fmt: skip
def test_outfit_bad_input_exits_2_naming_it(argv, message, no_model_loading, tmp_path, capsys):
    assert main(["outfit", "-o", str(tmp_path / "o.glb"), *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"ulnef outfit: {message}"), err
    assert not (tmp_path / "o.glb").exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["outfit", "--garments", "tshirt", "--threads", "0"], "argument --threads: 0 is less than 1"),
        (["outfit", "--garments", "tshirt", "--height-cm", "tall"],
         "argument --height-cm: invalid float value"),
        (["outfit"], "the following arguments are required: --garments"),
        (["avatar", "--units", "inch"], "argument --units: invalid choice: 'inch'"),
        (["garments", "--csv"], "unrecognized arguments: --csv"),
    ],
)  # fmt: skip
def test_argument_errors_exit_2_naming_the_option(argv, message, capsys):
    with pytest.raises(SystemExit) as exited:
        main(argv)
    assert exited.value.code == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize(
    ("name", "message"),
    [("avatar.txt", "avatar.txt: the file must end in .glb or .obj"),
     ("missing/avatar.obj", "cannot write")],
)  # fmt: skip
def test_avatar_bad_output_exits_2(name, message, tmp_path, capsys):
    target = tmp_path / name
    if name.startswith("missing"):
        (tmp_path / "missing").write_text("a file where the directory should be")
    assert main(["avatar", "-o", str(target)]) == 2
    assert message in capsys.readouterr().err
