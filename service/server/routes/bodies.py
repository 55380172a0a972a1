"""``POST /v1/bodies`` (a shopper's body alone: JSON or the GLB itself, by Accept) and ``GET
/v1/bodies.glb?<request>`` (any replica; ``service.server.outfit_url.BODIES``): the body an outfit
would be made on, from gender, height, weight and any of chest, waist and hip girths."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Header, Request, Response

from service.server import outfit_url
from service.server.routes.deps import TryOnDep, authorize
from service.server.routes.outfits import (
    ERRORS,
    GLB,
    GLB_CONTENT,
    IMMUTABLE,
    QUERY_PARAMETERS,
    REVALIDATE,
    accepts_glb,
    etag,
    glb_answer,
    json_body,
    matches,
    signed_by,
)
from service.server.runtime import body_id
from service.server.schemas import BodyCreated, BodyReport, BodyRequest, ErrorResponse

ID_HEADER = "X-Body-Id"

router = APIRouter(prefix="/v1", tags=["bodies"])

# The outfit URL's parameters that a body's URL has, with the bodies' POST named.
BODY_QUERY_PARAMETERS = [
    p | {"description": p["description"].replace("POST /v1/outfits", "POST /v1/bodies")}
    for p in QUERY_PARAMETERS
    if p["name"] in outfit_url.BODY_FIELDS or p["name"] in outfit_url.EXTRA
]


@router.post(
    "/bodies",
    response_model=BodyCreated,
    dependencies=[Depends(json_body)],
    responses={
        200: {"content": GLB_CONTENT, "description": f"The body: JSON, or the GLB for `Accept: {GLB}`."},
        406: {"model": ErrorResponse},
        **ERRORS,
    },
)
async def create_body(
    request: BodyRequest,
    tryon: TryOnDep,
    accept: Annotated[str | None, Header()] = None,
    authorization: Annotated[str | None, Header()] = None,
) -> Response | BodyCreated:
    """A shopper's body from gender, height, weight and any of chest, waist and hip girths (the others
    predicted), measured on its mesh. The GLB holds one node, `body`, whose glTF `extras.body` is the
    same measurements. `glb_url` is the GLB's URL on any replica (signed for the key, with API keys on)."""
    glb = accepts_glb(accept)
    kid = authorize(tryon, authorization)
    spec, compression = request.spec(), request.options.compression
    key, result, _ = await tryon.body(spec, compression)
    version = tryon.require_engine().model_version
    url = outfit_url.glb_url(spec, compression, version, kid, tryon.url_secret, outfit_url.BODIES)
    if glb:
        data = result.encoded(compression)
        return glb_answer(data, key, compression, IMMUTABLE, ID_HEADER, **{"Content-Location": url})
    return BodyCreated(body=BodyReport(**result.report["body"]), glb_url=url)


@router.get(
    outfit_url.BODY_PATH.removeprefix("/v1"),
    response_class=Response,
    responses={
        200: {
            "content": GLB_CONTENT,
            "description": "The body's GLB (`ETag`: the body's id; immutable when `v` is the serving "
            "model version).",
        },
        304: {"description": "`If-None-Match` names this body's ETag."},
        **{k: v for k, v in ERRORS.items() if k not in (413, 415)},
    },
    openapi_extra={"parameters": BODY_QUERY_PARAMETERS},
)
async def get_body_by_url(
    http: Request,
    tryon: TryOnDep,
    if_none_match: Annotated[str | None, Header()] = None,
    authorization: Annotated[str | None, Header()] = None,
) -> Response:
    """The GLB of the body the query describes, from any replica: built here (the same bytes as
    anywhere else) when this replica has not built it yet."""
    query = outfit_url.parse_query(list(http.query_params.multi_items()), outfit_url.BODIES)
    spec, compression = query.request.spec(), query.request.options.compression
    version = tryon.require_engine().model_version
    authorize(tryon, authorization, signed_by(tryon, query))
    key = body_id(spec, version)
    cache_control = IMMUTABLE if query.version == version else REVALIDATE
    tag = etag(key, compression)
    headers = {"ETag": tag, "Cache-Control": cache_control, ID_HEADER: key}
    if if_none_match is not None and matches(if_none_match, tag):
        return Response(status_code=304, headers=headers)
    key, result, _ = await tryon.body(spec, compression)
    return glb_answer(result.encoded(compression), key, compression, cache_control, ID_HEADER)
