"""Dependencies the routes share (FastAPI ``Depends``)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from service.server.runtime import TryOn
from service.server.settings import Settings


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


def get_tryon(request: Request) -> TryOn:
    return request.app.state.tryon


SettingsDep = Annotated[Settings, Depends(get_settings)]
TryOnDep = Annotated[TryOn, Depends(get_tryon)]
