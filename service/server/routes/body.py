"""``GET /v1/body/ranges``: the heights, weights and girths the body model accepts (the page's sliders
and girth inputs follow them; a request outside them is refused with a 422 naming the same bounds)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query
from fastapi.concurrency import run_in_threadpool

from service.pipeline.tryon import GIRTH_FIELDS
from service.server.routes.deps import TryOnDep
from service.server.schemas import HEIGHT_CM, WEIGHT_KG, BodyRanges, ErrorResponse, Range

router = APIRouter(prefix="/v1", tags=["body"])


@router.get(
    "/body/ranges",
    responses={422: {"model": ErrorResponse, "description": "A parameter is invalid."},
               503: {"model": ErrorResponse, "description": "Not ready; see Retry-After."}},  # fmt: skip
)
async def body_ranges(
    tryon: TryOnDep,
    gender: Annotated[float, Query(ge=0.0, le=1.0, allow_inf_nan=False,
                                   description="0 male .. 1 female.")] = 0.0,
    height_cm: Annotated[float | None, Query(ge=HEIGHT_CM[0], le=HEIGHT_CM[1], allow_inf_nan=False,
                                             description="Height the weight range is for (default: the "
                                             "middle of the height range).")] = None,
    weight_kg: Annotated[float | None, Query(ge=WEIGHT_KG[0], le=WEIGHT_KG[1], allow_inf_nan=False,
                                             description="Weight the girth ranges are for, at `height_cm` "
                                             "(default: the middle of the weight range).")] = None,
) -> BodyRanges:  # fmt: skip
    """Heights accepted, weights accepted at `height_cm`, and the chest, waist and hip girths accepted
    for `gender` at that height and `weight_kg`: bounds as refusals print them, each accepted itself."""
    ranges = await run_in_threadpool(tryon.require_engine().body_ranges, gender, height_cm, weight_kg)
    bounds = {name: Range(min=ranges[name][0], max=ranges[name][1])
              for name in ("height_cm", "weight_kg", *GIRTH_FIELDS)}  # fmt: skip
    return BodyRanges(gender=gender, weight_at_height_cm=ranges["at_height_cm"],
                      girths_at_weight_kg=ranges["at_weight_kg"], **bounds)  # fmt: skip
