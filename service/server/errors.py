"""Exceptions to HTTP answers: every 4xx names the field and what it accepts; overload and
deadlines answer 503/504 with Retry-After, never 500.

Body: ``{"detail": "body.height_cm: ...; allowed: ...", "errors": [{"field", "message", "allowed"}]}``.
"""

from __future__ import annotations

import re
from collections.abc import Callable

from fastapi import FastAPI, Request
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException

from service.pipeline.tryon import GARMENT_ID_RULE, InvalidField
from service.server import outfit_url
from service.server.runtime import NotReady
from service.server.schemas import ALLOWED, BODY_ALLOWED, FIT_ALLOWED
from service.server.worker import DeadlineExceeded, Overloaded

NOT_READY_RETRY_S = 5


class HeaderInvalid(Exception):
    """A request header the route cannot serve (``status`` 406 or 415), answered like any bad field."""

    def __init__(self, status: int, field: str, message: str, allowed: str):
        super().__init__(message)
        self.status, self.field, self.allowed = status, field, allowed


def _field_path(loc: tuple) -> str:
    """``("body", "body", "height_cm")`` -> ``body.height_cm``; request parts other than the body
    keep their part name (``path.outfit_id``)."""
    parts = [str(p) for p in loc]
    if parts and parts[0] == "body":
        parts = parts[1:]
    return ".".join(parts)


def _allowed(path: str, extra: bool, allowed: dict[str, str]) -> str:
    """The ``allowed`` entry for a field path: list indices dropped, an unknown field answered by its
    parent's entry (which lists the known fields)."""
    key = re.sub(r"\.\d+", "", path)
    if extra:
        key = key.rpartition(".")[0]
    return allowed.get(key, "see openapi.yaml")


def allowed_for(url_path: str) -> dict[str, str]:
    """What each field accepts on the route of ``url_path``: the bodies' routes have fewer fields."""
    if url_path.startswith("/v1/bodies"):
        return ALLOWED | BODY_ALLOWED
    return ALLOWED | FIT_ALLOWED if url_path.startswith("/v1/fit") else ALLOWED


# pydantic's names of the two forms of a ``garments`` item (an id, or ``SizedGarment``) in an error's loc
ITEM_FORMS = {"constrained-str": str, "SizedGarment": dict}


def _item_errors(errors: list[dict]) -> list[dict]:
    """``errors`` with each ``garments`` item judged by the form it was given in: a string's errors as an
    id, an object's as a ``SizedGarment`` (pydantic reports a bad item against both forms); the form
    named in the loc dropped. An item that is neither keeps one error."""
    out, seen = [], set()
    for e in errors:
        loc = tuple(e.get("loc", ()))
        forms = [i for i, p in enumerate(loc) if p in ITEM_FORMS]
        if not forms:
            out.append(e)
            continue
        i = forms[0]
        item = e.get("input") if len(loc) == i + 1 else None
        given = type(item) if item is not None else ITEM_FORMS[loc[i]]
        wrong_form = e.get("type") in ("string_type", "model_type") and len(loc) == i + 1
        if wrong_form and isinstance(item, (str, dict)) and not isinstance(item, ITEM_FORMS[loc[i]]):
            continue
        if wrong_form and given not in (str, dict):
            if loc[:i] in seen:
                continue
            seen.add(loc[:i])
            e = e | {"type": "garment_item", "msg": "Input should be a garment id or an object with `id` "
                     "and `size`"}  # fmt: skip
        out.append(e | {"loc": loc[:i] + loc[i + 1 :]})
    return out


def field_errors(errors: list[dict], garment_ids: list[str], allowed: dict[str, str] = ALLOWED) -> list[dict]:
    """pydantic/FastAPI error dicts -> ``[{"field", "message", "allowed"}]``, ``allowed`` as the route
    takes it (``allowed_for``)."""
    out = []
    for e in _item_errors(errors):
        path = _field_path(tuple(e.get("loc", ())))
        kind = e.get("type", "")
        if kind == "extra_forbidden":
            message = "unknown field"
        elif kind == "json_invalid":
            message = f"malformed JSON ({e.get('ctx', {}).get('error', 'decode error')})"
            path = ""
        elif kind == "string_pattern_mismatch" and path.startswith(("garments", "under", "style")):
            # a catalog id never breaks the id rule: say the id is unknown, and list the known ones
            message = f"unknown garment id {e.get('input')!r} (ids are {GARMENT_ID_RULE})"
        else:
            message = outfit_url.message(e)
        extra = kind == "extra_forbidden"
        accepts = _allowed(path, extra, allowed)
        names_id = path.startswith(("garments", "under", "style")) and not path.endswith(".size")
        if names_id and garment_ids and not extra:  # the ids it lacks
            accepts += ": " + ", ".join(garment_ids)
        out.append({"field": path or "(request body)", "message": message, "allowed": accepts})
    return out


def _summary(errors: list[dict]) -> str:
    return "; ".join(f"{e['field']}: {e['message']} (allowed: {e['allowed']})" for e in errors)


def install(app: FastAPI, garment_ids: Callable[[], list[str]]) -> None:
    @app.exception_handler(RequestValidationError)
    async def invalid_request(request: Request, exc: RequestValidationError) -> JSONResponse:
        errors = field_errors(list(exc.errors()), garment_ids(), allowed_for(request.url.path))
        return JSONResponse({"detail": _summary(errors), "errors": errors}, status_code=422)

    @app.exception_handler(HTTPException)
    async def http_error(request: Request, exc: HTTPException):
        # FastAPI's only 400 is a body it could not decode (e.g. not UTF-8): answer it like
        # malformed JSON, so every bad body is a 422 that says what is allowed.
        if exc.status_code == 400:
            errors = [{"field": "(request body)", "message": "malformed JSON (not UTF-8 text)",
                       "allowed": allowed_for(request.url.path)[""]}]  # fmt: skip
            return JSONResponse({"detail": _summary(errors), "errors": errors}, status_code=422)
        return await http_exception_handler(request, exc)

    @app.exception_handler(outfit_url.QueryInvalid)
    async def invalid_query(request: Request, exc: outfit_url.QueryInvalid) -> JSONResponse:
        errors = field_errors(exc.errors, garment_ids(), allowed_for(request.url.path))
        return JSONResponse({"detail": _summary(errors), "errors": errors}, status_code=422)

    @app.exception_handler(InvalidField)
    async def invalid_field(request: Request, exc: InvalidField) -> JSONResponse:
        errors = [{"field": exc.field, "message": str(exc), "allowed": exc.allowed}]
        return JSONResponse({"detail": _summary(errors), "errors": errors}, status_code=422)

    @app.exception_handler(HeaderInvalid)
    async def invalid_header(request: Request, exc: HeaderInvalid) -> JSONResponse:
        errors = [{"field": exc.field, "message": str(exc), "allowed": exc.allowed}]
        return JSONResponse({"detail": _summary(errors), "errors": errors}, status_code=exc.status)

    @app.exception_handler(NotReady)
    async def not_ready(request: Request, exc: NotReady) -> JSONResponse:
        headers = {"Retry-After": str(NOT_READY_RETRY_S)}
        return JSONResponse({"detail": f"not ready: {exc}"}, status_code=503, headers=headers)

    @app.exception_handler(Overloaded)
    async def overloaded(request: Request, exc: Overloaded) -> JSONResponse:
        headers = {"Retry-After": str(exc.retry_after)}
        return JSONResponse({"detail": f"overloaded: {exc}"}, status_code=503, headers=headers)

    @app.exception_handler(DeadlineExceeded)
    async def deadline(request: Request, exc: DeadlineExceeded) -> JSONResponse:
        headers = {"Retry-After": str(NOT_READY_RETRY_S)}
        return JSONResponse({"detail": f"deadline exceeded: {exc}"}, status_code=504, headers=headers)
