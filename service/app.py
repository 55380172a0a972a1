"""The HTTP app: routes translate HTTP to ``service`` calls and nothing else."""

from __future__ import annotations

import logging
import zipfile
from importlib.metadata import PackageNotFoundError, version
from typing import Annotated, Literal

from fastapi import APIRouter, Depends, FastAPI, HTTPException, Request, Response
from fastapi.middleware.cors import CORSMiddleware
from fastapi.routing import APIRoute
from pydantic import BaseModel, ConfigDict, Field

from service.catalog import Category, Garment, load_catalog
from service.settings import Settings

log = logging.getLogger(__name__)
CATALOG_NOT_LOADED = "garment catalog not loaded"
# What a missing, partial or corrupt catalog raises; anything else is a bug and should surface.
CATALOG_ERRORS = (OSError, ValueError, KeyError, zipfile.BadZipFile)


class GarmentSummary(BaseModel):
    model_config = ConfigDict(
        json_schema_extra={
            "example": {
                "id": "tshirt",
                "name": "T-shirt",
                "category": "top",
                "layer_rank": 1,
                "vertices": 5210,
                "faces": 10128,
                "openings": ["left_sleeve", "neck", "right_sleeve", "waist"],
            }
        }
    )

    id: str = Field(description="Garment id, as used in outfit requests.")
    name: str = Field(description="Human-readable name.")
    category: Category = Field(description="`top` or `bottom`.")
    layer_rank: int = Field(description="Default stacking rank in its category; lower is nearer the body.")
    vertices: int = Field(description="Vertex count of the rest mesh.")
    faces: int = Field(description="Triangle count of the rest mesh.")
    openings: list[str] = Field(description="Names of the garment's openings (boundary loops), sorted.")


class GarmentList(BaseModel):
    garments: list[GarmentSummary] = Field(description="Every catalog garment, in catalog order.")


class Health(BaseModel):
    status: Literal["ok"] = Field(description="Always `ok`: the process answers.")


class Readiness(BaseModel):
    ready: bool = Field(description="Whether the models are loaded and requests can be served.")
    garments: int | None = Field(default=None, description="Number of catalog garments, when ready.")
    detail: str | None = Field(default=None, description="Why the service is not ready.")


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


SettingsDep = Annotated[Settings, Depends(get_settings)]


def try_load_catalog(settings: Settings) -> dict[str, Garment] | None:
    try:
        return load_catalog(settings.garments_dir())
    except CATALOG_ERRORS as e:
        log.warning("%s: %s", CATALOG_NOT_LOADED, e)
        return None


def get_catalog(settings: SettingsDep) -> dict[str, Garment]:
    catalog = try_load_catalog(settings)
    if catalog is None:
        raise HTTPException(status_code=503, detail=CATALOG_NOT_LOADED)
    return catalog


CatalogDep = Annotated[dict[str, Garment], Depends(get_catalog)]

probes = APIRouter(tags=["probes"])
garments = APIRouter(prefix="/v1", tags=["garments"])


@probes.get("/healthz")
def healthz() -> Health:
    """Liveness: the process answers."""
    return Health(status="ok")


@probes.get("/readyz", response_model_exclude_none=True, responses={503: {"model": Readiness}})
def readyz(settings: SettingsDep, response: Response) -> Readiness:
    """Readiness: the garment catalog loads."""
    catalog = try_load_catalog(settings)
    if catalog is None:
        response.status_code = 503
        return Readiness(ready=False, detail=CATALOG_NOT_LOADED)
    return Readiness(ready=True, garments=len(catalog))


@garments.get("/garments", responses={503: {"description": CATALOG_NOT_LOADED}})
def list_garments(catalog: CatalogDep) -> GarmentList:
    """The garment catalog."""
    return GarmentList(garments=[GarmentSummary(**g.summary()) for g in catalog.values()])


def package_version() -> str:
    try:
        return version("ulnef")
    except PackageNotFoundError:  # running from a source tree that was never installed
        return "0.0.0"


def operation_id(route: APIRoute) -> str:
    """Operation ids are the route functions' names (``list_garments``), for generated clients."""
    return route.name


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings if settings is not None else Settings()
    app = FastAPI(
        title="ULNeF try-on service",
        version=package_version(),
        generate_unique_id_function=operation_id,
    )
    app.state.settings = settings
    if settings.cors_origins:
        app.add_middleware(CORSMiddleware, allow_origins=settings.cors_origins, allow_methods=["GET", "POST"])
    app.include_router(probes)
    app.include_router(garments)
    return app


app = create_app()
