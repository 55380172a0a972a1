"""``GET /v1/body/ranges``: the heights and weights the body model accepts for a gender (the page's
sliders follow them; a request outside them is refused with a 422 naming the same bounds)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query
from fastapi.concurrency import run_in_threadpool

from service.server.routes.deps import TryOnDep
from service.server.schemas import HEIGHT_CM, BodyRanges, ErrorResponse, Range

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
) -> BodyRanges:  # fmt: skip
    """Heights accepted for `gender`, and weights accepted at `height_cm`: bounds as refusals print
    them, each accepted itself."""
    ranges = await run_in_threadpool(tryon.require_engine().body_ranges, gender, height_cm)
    (h_lo, h_hi), (w_lo, w_hi) = ranges["height_cm"], ranges["weight_kg"]
    return BodyRanges(gender=gender, height_cm=Range(min=h_lo, max=h_hi), weight_kg=Range(min=w_lo, max=w_hi),
                      weight_at_height_cm=ranges["at_height_cm"])  # fmt: skip
