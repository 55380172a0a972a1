"""``POST /v1/outfits`` (JSON or the GLB itself, by Accept) and ``GET /v1/outfits/{id}.glb``."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Header, HTTPException, Path, Response

from service.server.routes.deps import TryOnDep
from service.server.schemas import ErrorResponse, OutfitCreated, OutfitRequest

GLB = "model/gltf-binary"
JSON = "application/json"
OUTFIT_ID = r"^[0-9a-f]{32}$"
# The id hashes the request and the model version, so the bytes behind a URL never change.
IMMUTABLE = "public, max-age=31536000, immutable"

router = APIRouter(prefix="/v1", tags=["outfits"])

ERRORS = {
    413: {"model": ErrorResponse, "description": "Request body over the size limit."},
    422: {"model": ErrorResponse, "description":
          "A field is invalid; the message names it and what it allows."},
    503: {"model": ErrorResponse, "description": "Not ready, or overloaded; see Retry-After."},
    504: {"model": ErrorResponse, "description": "The request's time budget ran out; see Retry-After."},
}
GLB_CONTENT = {GLB: {"schema": {"type": "string", "format": "binary"}}}


def _quality(accept: str, media_type: str) -> tuple[float, int]:
    """(q, specificity 0-2) of the most specific range in ``accept`` matching ``media_type``."""
    kind = media_type.split("/")[0]
    best = (0.0, -1)
    for item in accept.split(","):
        rng, *params = (p.strip() for p in item.split(";"))
        q = 1.0
        for p in params:
            name, _, value = p.partition("=")
            if name.strip() == "q":
                try:
                    q = float(value)
                except ValueError:
                    q = 0.0
        spec = {media_type: 2, f"{kind}/*": 1, "*/*": 0}.get(rng.lower())
        if spec is not None and spec > best[1]:
            best = (q, spec)
    return best


def wants_glb(accept: str | None) -> bool | None:
    """True for the GLB, False for JSON, None when the Accept header allows neither.
    JSON wins ties unless the GLB is named more specifically (``model/gltf-binary, */*``)."""
    if not accept:
        return False
    glb, json_ = _quality(accept, GLB), _quality(accept, JSON)
    if glb[0] <= 0 and json_[0] <= 0:
        return None
    return glb > json_


@router.post(
    "/outfits",
    response_model=OutfitCreated,
    responses={200: {"content": GLB_CONTENT, "description": "The outfit: JSON, or the GLB for "
                     f"`Accept: {GLB}`."}, 406: {"model": ErrorResponse}, **ERRORS},  # fmt: skip
)
async def create_outfit(
    request: OutfitRequest, tryon: TryOnDep, accept: Annotated[str | None, Header()] = None
) -> Response | OutfitCreated:
    """Dress a body in garments (inner to outer). Repeated requests are served from a cache."""
    glb = wants_glb(accept)
    if glb is None:
        raise HTTPException(406, detail=f"Accept: allowed {JSON} (default) or {GLB}")
    outfit_id, result, cached = await tryon.outfit(request.spec())
    url = f"/v1/outfits/{outfit_id}.glb"
    if glb:
        headers = {"X-Outfit-Id": outfit_id, "Content-Location": url, "Cache-Control": IMMUTABLE}
        return Response(result.glb, media_type=GLB, headers=headers)
    return OutfitCreated(id=outfit_id, glb_url=url, cached=cached, report=result.report)


@router.get(
    "/outfits/{outfit_id}.glb",
    response_class=Response,
    responses={200: {"content": GLB_CONTENT, "description": "The outfit's GLB."},
               404: {"model": ErrorResponse, "description": "Not in the cache: POST the request again."},
               422: ERRORS[422]},  # fmt: skip
)
def get_outfit_glb(
    outfit_id: Annotated[str, Path(pattern=OUTFIT_ID, description="`id` from POST /v1/outfits.")],
    tryon: TryOnDep,
) -> Response:
    """The GLB of an outfit made recently (usable as a 3D model URL). Outfits live in an LRU cache;
    an evicted one answers 404 and is made again by repeating its POST."""
    data = tryon.cached_glb(outfit_id)
    if data is None:
        detail = f"outfit {outfit_id} is not in the cache (evicted, or never made): POST /v1/outfits again"
        raise HTTPException(404, detail=detail)
    return Response(data, media_type=GLB, headers={"Cache-Control": IMMUTABLE, "ETag": f'"{outfit_id}"'})
