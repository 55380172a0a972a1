"""``POST /v1/admin/reload``: pick up newly imported garments without a restart (token protected).

Disabled (404) unless ``ULNEF_ADMIN_TOKEN`` is set; the token comes as ``Authorization: Bearer ...``
and is compared in constant time. ``SIGHUP`` to the server process does the same (``app.py``).
"""

from __future__ import annotations

import hmac
from typing import Annotated

from fastapi import APIRouter, Header, HTTPException
from fastapi.concurrency import run_in_threadpool

from service.server.routes.deps import SettingsDep, TryOnDep
from service.server.runtime import ReloadBusy
from service.server.schemas import ErrorResponse, ReloadResult

router = APIRouter(prefix="/v1/admin", tags=["admin"])
DISABLED = "admin endpoint disabled (set ULNEF_ADMIN_TOKEN)"
BAD_TOKEN = "missing or wrong admin token (Authorization: Bearer <ULNEF_ADMIN_TOKEN>)"


@router.post(
    "/reload",
    responses={
        401: {"model": ErrorResponse, "description": BAD_TOKEN},
        404: {"model": ErrorResponse, "description": DISABLED},
        409: {"model": ErrorResponse, "description": "a reload is already running"},
        503: {"model": ErrorResponse, "description": "the new models failed; the old ones still serve"},
    },
)
async def reload_models(
    settings: SettingsDep, tryon: TryOnDep, authorization: Annotated[str | None, Header()] = None
) -> ReloadResult:
    """Load the models and every verified import again, self-test, then serve them."""
    if settings.admin_token is None:
        raise HTTPException(status_code=404, detail=DISABLED)
    expected = f"Bearer {settings.admin_token.get_secret_value()}"
    if authorization is None or not hmac.compare_digest(authorization.encode(), expected.encode()):
        raise HTTPException(status_code=401, detail=BAD_TOKEN)
    try:
        return ReloadResult(**await run_in_threadpool(tryon.reload))
    except ReloadBusy as e:
        raise HTTPException(status_code=409, detail=str(e)) from None
    except Exception as e:  # the serving engine is untouched; say why the new one is not served
        raise HTTPException(status_code=503, detail=f"reload failed: {type(e).__name__}: {e}") from None
