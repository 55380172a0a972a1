"""Liveness, readiness and Prometheus metrics."""

from __future__ import annotations

from fastapi import APIRouter, Response

from service.server.metrics import CONTENT_TYPE
from service.server.routes.deps import TryOnDep
from service.server.schemas import Health, Readiness

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
                     "description": "Prometheus text format."}},  # fmt: skip
)
def metrics(tryon: TryOnDep) -> Response:
    """Prometheus metrics: requests, latency per route and per pipeline stage, cache, queue depth."""
    return Response(tryon.metrics.render(), media_type=CONTENT_TYPE)
