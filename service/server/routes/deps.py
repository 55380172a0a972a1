"""Dependencies the routes share (FastAPI ``Depends``)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, HTTPException, Request

from service.server.runtime import TryOn
from service.server.settings import Settings


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


def get_tryon(request: Request) -> TryOn:
    return request.app.state.tryon


SettingsDep = Annotated[Settings, Depends(get_settings)]
TryOnDep = Annotated[TryOn, Depends(get_tryon)]


NO_KEY = "missing or unknown API key: send `Authorization: Bearer <key>` (ask the operator for a key)"


def authorize(tryon: TryOn, authorization: str | None, signed_by: str | None = None) -> str | None:
    """The key id an outfit request counts against (None with keys off); raises 401 without a valid
    key (or a valid URL signature: ``signed_by``, checked by the caller) and 429 over its rate."""
    if tryon.keys is None:
        return None
    kid = tryon.keys.identify(authorization) or signed_by
    if kid is None:
        raise HTTPException(401, detail=NO_KEY, headers={"WWW-Authenticate": "Bearer"})
    wait = tryon.limiter.take(kid)
    if wait is not None:
        tryon.metrics.rejected.labels("rate_limit").inc()
        detail = f"rate limit of key {kid}: {tryon.settings.rate_limit_per_minute:g} outfit requests a minute"
        raise HTTPException(429, detail=detail, headers={"Retry-After": str(int(wait))})
    return kid
