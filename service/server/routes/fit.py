"""``POST /v1/fit``: which size of a style to buy, and how each size fits, on a shopper's body over
the layers she wears under it (issue 56, docs/fit.md)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Header

from service.server.routes.deps import TryOnDep, authorize
from service.server.routes.outfits import ERRORS, json_body
from service.server.schemas import FitAnswer, FitRequest

router = APIRouter(prefix="/v1", tags=["fit"])


@router.post("/fit", response_model=FitAnswer, dependencies=[Depends(json_body)], responses=ERRORS)
async def fit(
    request: FitRequest, tryon: TryOnDep, authorization: Annotated[str | None, Header()] = None
) -> FitAnswer:
    """Each size of `style` on the body, by region: the size's girth (its finished measurement), the
    tape over the body and the garments `under` it there, and the ease between them; and the size the
    rule (`rule`, docs/fit.md) recommends, with its runner-up where the choice is close. An unknown
    style, or one without sizes, is a 422 naming the styles with sizes."""
    authorize(tryon, authorization)
    return FitAnswer(**await tryon.fit(request.spec(), request.style))
