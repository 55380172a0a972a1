from __future__ import annotations

import json
from pathlib import Path

import pytest
import uvicorn
from fastapi import FastAPI

from service.cli import main
from service.process.paths import REPO_ROOT

TABLE = """\
id      name     category  layer rank  vertices  faces  openings     sizes
tshirt  T-shirt  top       1           4         2      neck, waist  XS, S, M, L, XL, XXL
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
        "sizes": ["XS", "S", "M", "L", "XL", "XXL"],
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
        (["--garments", "pants,tshirt:XXXL"], "--garments: 'tshirt' has no size 'XXXL'; its sizes: XS, S, M, "
         "L, XL, XXL"),
        (["--garments", "tshirt", "-o", "/nonexistent-dir/x.glb"], "-o /nonexistent-dir/x.glb: no such "
         "directory /nonexistent-dir"),
        (["--garments", "tshirt", "--gender", "1", "--height-cm", "134.9"], "--height-cm: height_cm=134.9 is "
         "outside the supported range 135.0-210.0 cm"),
        (["--garments", "tshirt", "--height-cm", "150", "--weight-kg", "300"],
         "--weight-kg: weight_kg=300 is outside the supported range 29.3-157.5 kg for height_cm=150 "
         "(BMI 13-70)"),
        (["--garments", "tshirt", "--gender", "1", "--height-cm", "165", "--weight-kg", "60",
          "--hip-cm", "300"], "--hip-cm: hip_cm=300 is outside the range "),
        (["--garments", "tshirt", "--chest-cm", "nan"], "--chest-cm: chest_cm=nan is not a finite number"),
        (["--garments", "tshirt", "--waist-cm", "-70"], "--waist-cm: waist_cm=-70 is outside the range "),
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
        (["outfit", "--garments", "tshirt", "--hip-cm", "wide"], "argument --hip-cm: invalid float value"),
        (["avatar", "--chest-cm", "broad"], "argument --chest-cm: invalid float value"),
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


# ---------------------------------------------------------------- a shopper's body: ulnef avatar --hip-cm ...


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--height-cm", "170", "-o", "body.obj"], "body.obj: a shopper's body is written as .glb"),
        (["--gender", "1", "--height-cm", "165", "--weight-kg", "60", "--hip-cm", "300"],
         "--hip-cm: hip_cm=300 is outside the range "),
        (["--gender", "1", "--height-cm", "165", "--weight-kg", "60", "--waist-cm", "100", "--hip-cm", "72"],
         "--waist-cm: no body has waist_cm, hip_cm together as given"),
        (["--weight-kg", "20"], "--weight-kg: weight_kg=20 is outside the supported range 41.2-221.7 kg for "
         "height_cm=178 (BMI 13-70)"),
    ],
)  # fmt: skip
def test_avatar_refuses_a_body_out_of_range_with_exit_2(argv, message, tmp_path, capsys):
    argv = (
        ["-o", str(tmp_path / "body.glb"), *argv]
        if "-o" not in argv
        else [a if a != "body.obj" else str(tmp_path / a) for a in argv]
    )
    assert main(["avatar", *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ulnef avatar: ") and message in err, err
    assert not list(tmp_path.iterdir())


def test_avatar_writes_a_shoppers_body_and_prints_its_measurements(tmp_path, capsys):
    """The body POST /v1/bodies makes: given values reproduced (issue 55's tolerances), the rest
    predicted, the same measurements on the GLB's body node."""
    from tests.server.test_api_bodies import body_node

    target = tmp_path / "shopper.glb"
    assert main(["avatar", "--gender", "1", "--height-cm", "165", "--weight-kg", "60", "--hip-cm", "100",
                 "-o", str(target)]) == 0  # fmt: skip
    report = json.loads(capsys.readouterr().out)
    body = report["body"]
    assert body["predicted"] == ["chest_cm", "waist_cm"]
    assert abs(body["height_cm"] - 165) <= 0.5 and abs(body["weight_kg"] - 60) <= 0.6
    assert abs(body["hip_cm"] - 100) <= 1.0
    assert body_node(target.read_bytes())["extras"] == report
    assert not target.with_suffix(".json").exists()  # avatar.json is the mean avatar's, for garment import


def test_fit_prints_each_size_and_the_size_to_buy(capsys):
    argv = ["fit", "--style", "tshirt", "--height-cm", "178", "--weight-kg", "80", "--threads", "1"]
    assert main(argv) == 0
    answer = json.loads(capsys.readouterr().out)
    assert answer["style"] == "tshirt" and answer["recommended"]["size"] in answer["sizes"]
    assert answer["body"]["height_cm"] == 178.0


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--style", "hat"], "ulnef fit: --style: unknown garment 'hat' has no sizes (allowed: one of"),
        (["--style", "jacket", "--under", "jacket"], "ulnef fit: --under: 'jacket' is the style fitted"),
        (["--style", "jacket", "--height-cm", "300"], "ulnef fit: --height-cm: "),
    ],
)
def test_fit_refuses_what_it_cannot_fit_with_exit_2(argv, message, capsys):
    assert main(["fit", *argv, "--threads", "1"]) == 2
    assert capsys.readouterr().err.startswith(message)
