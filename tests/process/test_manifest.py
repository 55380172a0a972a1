"""Tests of ``service/process/manifest.py`` and ``export/manifest.py``.

The committed ``models/manifest.json`` must match ``models/`` byte for byte; refresh it with
``python -m export.manifest`` after changing any model file.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from export.manifest import build_manifest, write_manifest
from service.process.manifest import (
    FORMAT_VERSION,
    MANIFEST_NAME,
    load_manifest,
    model_files,
    verify_manifest,
)
from service.process.paths import REPO_ROOT

MODELS = REPO_ROOT / "models"


@pytest.fixture
def models_copy(tmp_path: Path) -> Path:
    """A copy of the models directory with a manifest written for the copy, so that these tests
    do not depend on the committed manifest being current."""
    directory = Path(shutil.copytree(MODELS, tmp_path / "models"))
    write_manifest(directory)
    return directory


def test_committed_manifest_verifies():
    problems = verify_manifest(MODELS)
    assert problems == [], (
        "models/manifest.json does not match models/; run `python -m export.manifest` after changing "
        "models and commit the manifest:\n" + "\n".join(problems)
    )


def test_committed_manifest_lists_every_model_file():
    manifest = load_manifest(MODELS)
    assert manifest.format_version == FORMAT_VERSION
    assert [e.path for e in manifest.files] == model_files(MODELS)
    assert "body/anny_shape.npz" in {e.path for e in manifest.files}
    assert MANIFEST_NAME not in {e.path for e in manifest.files}
    assert set(manifest.producers) >= {"anny", "numpy"}


def test_manifest_is_deterministic(models_copy: Path):
    before = (models_copy / MANIFEST_NAME).read_text()
    write_manifest(models_copy)
    assert (models_copy / MANIFEST_NAME).read_text() == before
    assert json.loads(before) == build_manifest(models_copy)
    assert verify_manifest(models_copy) == []


def test_modified_byte_is_a_sha256_problem(models_copy: Path):
    target = models_copy / "garments" / "catalog.json"
    data = bytearray(target.read_bytes())
    data[len(data) // 2] ^= 0x01
    target.write_bytes(bytes(data))
    problems = verify_manifest(models_copy)
    assert len(problems) == 1
    assert problems[0].startswith("garments/catalog.json: sha256 mismatch (expected ")


def test_deleted_file_is_missing(models_copy: Path):
    (models_copy / "garments" / "skirt.npz").unlink()
    problems = verify_manifest(models_copy)
    assert len(problems) == 1
    assert problems[0].startswith("garments/skirt.npz: missing")


def test_extra_file_is_unlisted(models_copy: Path):
    (models_copy / "garments" / "extra.npz").write_bytes(b"not a model")
    problems = verify_manifest(models_copy)
    assert len(problems) == 1
    assert problems[0].startswith("garments/extra.npz: unlisted")


def test_truncated_file_reports_size_and_sha256(models_copy: Path):
    target = models_copy / "body" / "anny_shape.npz"
    target.write_bytes(target.read_bytes()[:-10])
    problems = verify_manifest(models_copy)
    assert [p.split(":")[0] for p in problems] == ["body/anny_shape.npz"] * 2
    assert "size mismatch" in problems[0] and "sha256 mismatch" in problems[1]


def test_absent_manifest_is_a_problem_not_an_exception(models_copy: Path):
    (models_copy / MANIFEST_NAME).unlink()
    problems = verify_manifest(models_copy)
    assert len(problems) == 1
    assert "python -m export.manifest" in problems[0]
    with pytest.raises(FileNotFoundError, match="python -m export.manifest"):
        load_manifest(models_copy)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{not json", "not valid JSON"),
        (json.dumps({"format_version": 2, "files": []}), "format_version must be 1, got 2"),
        (json.dumps({"format_version": 1, "ulnef_version": "0", "files": [{"path": "a"}]}), "malformed"),
        (
            json.dumps(
                {
                    "format_version": 1,
                    "ulnef_version": "0",
                    "files": [{"path": "../escape", "size": 0, "sha256": ""}],
                }
            ),
            "must be relative",
        ),
    ],
)
def test_bad_manifest_is_rejected(models_copy: Path, content: str, message: str):
    (models_copy / MANIFEST_NAME).write_text(content)
    with pytest.raises(ValueError, match=message):
        load_manifest(models_copy)
    problems = verify_manifest(models_copy)
    assert len(problems) == 1 and message in problems[0]
