"""Liveness, readiness and Prometheus metrics."""

from __future__ import annotations

import hmac
from typing import Annotated

from fastapi import APIRouter, Header, HTTPException, Response

from service.server.metrics import CONTENT_TYPE
from service.server.routes.deps import SettingsDep, TryOnDep
from service.server.schemas import ErrorResponse, Health, Readiness

BAD_METRICS_TOKEN = "missing or wrong metrics token (Authorization: Bearer <ULNEF_METRICS_TOKEN>)"

router = APIRouter(tags=["probes"])


@router.get("/healthz")
def healthz() -> Health:
    """Liveness: the process answers (true while models still load)."""
    return Health(status="ok")


@router.get("/readyz", response_model_exclude_none=True, responses={503: {"model": Readiness}})
def readyz(tryon: TryOnDep, response: Response) -> Readiness:
    """Readiness: models verified and loaded, and the start-up self-test outfit passed."""
    if not tryon.ready or tryon.engine is None:
        response.status_code = 503
        return Readiness(ready=False, detail=tryon.detail)
    engine = tryon.engine
    return Readiness(ready=True, garments=len(engine.garment_ids()), model_version=engine.model_version)


@router.get(
    "/metrics",
    response_class=Response,
    responses={200: {"content": {CONTENT_TYPE: {"schema": {"type": "string"}}},
                     "description": "Prometheus text format."},
               401: {"model": ErrorResponse, "description": BAD_METRICS_TOKEN}},  # fmt: skip
)
def metrics(
    tryon: TryOnDep, settings: SettingsDep, authorization: Annotated[str | None, Header()] = None
) -> Response:
    """Prometheus metrics: requests, latency per route and per pipeline stage, cache, queue depth.
    Behind a bearer token when ``ULNEF_METRICS_TOKEN`` is set."""
    if settings.metrics_token is not None:
        expected = f"Bearer {settings.metrics_token.get_secret_value()}"
        if authorization is None or not hmac.compare_digest(authorization.encode(), expected.encode()):
            raise HTTPException(401, detail=BAD_METRICS_TOKEN, headers={"WWW-Authenticate": "Bearer"})
    return Response(tryon.metrics.render(), media_type=CONTENT_TYPE)
