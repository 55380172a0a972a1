"""The garment catalog (read from disk: answers before the models finish loading)."""

from __future__ import annotations

import logging
import zipfile
from typing import Annotated

from fastapi import APIRouter, Depends, HTTPException

from service.pipeline.catalog import Garment, full_catalog
from service.pipeline.sizing import SIZES_NAME, load_sizes
from service.process.paths import models_dir
from service.server.routes.deps import SettingsDep, TryOnDep
from service.server.schemas import ErrorResponse, GarmentList, GarmentSummary
from service.server.settings import Settings

log = logging.getLogger(__name__)
CATALOG_NOT_LOADED = "garment catalog not loaded"
# What a missing, partial or corrupt catalog raises; anything else is a bug and should surface.
CATALOG_ERRORS = (OSError, ValueError, KeyError, zipfile.BadZipFile)

router = APIRouter(prefix="/v1", tags=["garments"])


def try_load_catalog(settings: Settings) -> dict[str, Garment] | None:
    try:
        return full_catalog(settings.catalog_dir(), settings.garments_dir)
    except CATALOG_ERRORS as e:
        log.warning("%s: %s", CATALOG_NOT_LOADED, e)
        return None


def get_catalog(settings: SettingsDep, tryon: TryOnDep) -> dict[str, Garment]:
    """The catalog on disk; once the models are loaded, only what they serve (an import published
    since start-up appears after a reload, when outfits can use it)."""
    catalog = try_load_catalog(settings)
    if catalog is None:
        raise HTTPException(status_code=503, detail=CATALOG_NOT_LOADED)
    if tryon.engine is not None:
        served = set(tryon.engine.garment_ids())
        catalog = {gid: g for gid, g in catalog.items() if gid in served}
    return catalog


CatalogDep = Annotated[dict[str, Garment], Depends(get_catalog)]


@router.get("/garments", responses={503: {"model": ErrorResponse, "description": CATALOG_NOT_LOADED}})
def list_garments(catalog: CatalogDep, settings: SettingsDep) -> GarmentList:
    """The garment catalog, with the sizes each garment comes in."""
    sizes = catalog_sizes(settings)
    return GarmentList(
        garments=[GarmentSummary(**g.summary(), sizes=sizes.get(gid, [])) for gid, g in catalog.items()]
    )


def catalog_sizes(settings: Settings) -> dict[str, list[str]]:
    """Garment id -> its sizes, smallest first (``sizes.json`` beside the catalog; none: one size each)."""
    path = (settings.catalog_dir() or models_dir() / "garments") / SIZES_NAME
    if not path.is_file():
        return {}
    return {style: list(entry["girths"]) for style, entry in load_sizes(path)["styles"].items()}
