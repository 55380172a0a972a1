"""The try-on page at ``/``, its static files (vendored, never a CDN: it works offline), and the API
description at ``/openapi.yaml`` (the committed file's text; ``/openapi.json`` is FastAPI's own)."""

from __future__ import annotations

from pathlib import Path

import yaml
from fastapi import APIRouter, Request, Response
from fastapi.responses import FileResponse
from fastapi.staticfiles import StaticFiles

STATIC_DIR = Path(__file__).resolve().parents[1] / "static"

router = APIRouter(include_in_schema=False)


@router.get("/")
def page() -> FileResponse:
    return FileResponse(STATIC_DIR / "index.html", media_type="text/html")


@router.get("/favicon.ico")
def favicon() -> Response:
    """No icon here (the page links ``/static/favicon.svg``): 204, not a 404 in every browser's log."""
    return Response(status_code=204)


def static_files() -> StaticFiles:
    return StaticFiles(directory=STATIC_DIR)


class _NoAliasDumper(yaml.SafeDumper):
    """Writes shared sub-objects out in full instead of as YAML anchors, so the file reads plainly."""

    def ignore_aliases(self, data) -> bool:
        return True


def openapi_yaml(schema: dict) -> str:
    """An OpenAPI schema as YAML, keys in FastAPI's order (stable across runs): ``openapi.yaml``."""
    return yaml.dump(schema, Dumper=_NoAliasDumper, sort_keys=False, allow_unicode=True, width=100)


@router.get("/openapi.yaml")
def openapi_document(request: Request) -> Response:
    return Response(openapi_yaml(request.app.openapi()), media_type="application/yaml")
