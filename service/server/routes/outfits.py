"""``POST /v1/outfits`` (JSON or the GLB itself, by Accept), ``GET /v1/outfits.glb?<request>`` (any
replica; ``service.server.outfit_url``) and ``GET /v1/outfits/{id}.glb`` (this replica's cache only)."""

from __future__ import annotations

import hmac
from typing import Annotated

from fastapi import APIRouter, Depends, Header, HTTPException, Path, Request, Response

from service.pipeline.sizes import LETTERS
from service.pipeline.tryon import GARMENT_ID, GIRTH_FIELDS
from service.server import outfit_url
from service.server.errors import HeaderInvalid
from service.server.routes.deps import TryOnDep, authorize
from service.server.runtime import TryOn
from service.server.schemas import ErrorResponse, OutfitCreated, OutfitRequest

GLB = "model/gltf-binary"
JSON = "application/json"
OUTFIT_ID = r"^[0-9a-f]{32}$"
# The id hashes the request and the model version, so the bytes behind a URL never change.
IMMUTABLE = "public, max-age=31536000, immutable"
# A GLB URL of another model version (or none) gets the serving models' outfit: revalidate it.
REVALIDATE = "public, no-cache"

router = APIRouter(prefix="/v1", tags=["outfits"])

ERRORS = {
    401: {"model": ErrorResponse, "description": "API keys are on and no valid key was sent."},
    413: {"model": ErrorResponse, "description": "Request body over the size limit."},
    422: {"model": ErrorResponse, "description":
          "A field is invalid; the message names it and what it allows."},
    415: {"model": ErrorResponse, "description": "The body is not `application/json`."},
    429: {"model": ErrorResponse, "description": "The key's rate limit; see Retry-After."},
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


def json_body(content_type: Annotated[str | None, Header()] = None) -> None:
    """415 for a body that is not JSON (FastAPI would read it as a string and complain about types)."""
    kind = (content_type or JSON).split(";")[0].strip().lower()
    if kind != JSON and not kind.endswith("+json"):
        raise HeaderInvalid(415, "header.content-type", f"{kind!r} is not JSON", f"{JSON} (or a +json type)")


def etag(outfit_id: str, compression: str) -> str:
    """Strong ETag of one encoding of an outfit: the outfit id, suffixed for a compact encoding."""
    return f'"{outfit_id}"' if compression == "none" else f'"{outfit_id}-{compression}"'


def matches(if_none_match: str, tag: str) -> bool:
    """Whether ``If-None-Match`` names ``tag``: weak comparison (RFC 9110 13.1.2), because a proxy that
    gzips the GLB (deploy/nginx) hands out ``W/"<id>"``; ``*`` matches any answer."""
    tags = {t.strip().removeprefix("W/") for t in if_none_match.split(",")}
    return "*" in tags or tag.removeprefix("W/") in tags


def glb_answer(data: bytes, outfit_id: str, compression: str, cache_control: str,
               id_header: str = "X-Outfit-Id", **headers) -> Response:  # fmt: skip
    headers = {"ETag": etag(outfit_id, compression), "Cache-Control": cache_control, id_header: outfit_id,
               **headers}  # fmt: skip
    return Response(data, media_type=GLB, headers=headers)


def signed_by(tryon: TryOn, query: outfit_url.GlbQuery) -> str | None:
    """The key id whose valid signature the GLB URL ``query`` carries (API keys and a URL secret on), or
    None."""
    if tryon.keys is None or tryon.url_secret is None or not (query.key_id and query.sig):
        return None
    spec, compression = query.request.spec(), query.request.options.compression
    expected = outfit_url.signature(tryon.url_secret, query.key_id, spec, compression, query.version or "")
    if hmac.compare_digest(expected, query.sig) and tryon.keys.knows(query.key_id):
        return query.key_id
    return None


def accepts_glb(accept: str | None) -> bool:
    """``wants_glb``, with a 406 where the Accept header allows neither answer."""
    glb = wants_glb(accept)
    if glb is None:
        raise HeaderInvalid(406, "header.accept", f"{accept!r} allows neither answer",
                            f"{JSON} (default) or {GLB}")  # fmt: skip
    return glb


def signed_url(tryon: TryOn, request: OutfitRequest, kid: str | None) -> str:
    version = tryon.require_engine().model_version
    return outfit_url.glb_url(request.spec(), request.options.compression, version, kid, tryon.url_secret)


@router.post(
    "/outfits",
    response_model=OutfitCreated,
    dependencies=[Depends(json_body)],
    responses={200: {"content": GLB_CONTENT, "description": "The outfit: JSON, or the GLB for "
                     f"`Accept: {GLB}`."}, 406: {"model": ErrorResponse}, **ERRORS},  # fmt: skip
)
async def create_outfit(
    request: OutfitRequest, tryon: TryOnDep, accept: Annotated[str | None, Header()] = None,
    authorization: Annotated[str | None, Header()] = None,
) -> Response | OutfitCreated:  # fmt: skip
    """Dress a body in garments (inner to outer). Repeated requests are served from a cache. `glb_url`
    is the GLB's URL on any replica (signed for the key, with API keys on)."""
    glb = accepts_glb(accept)
    kid = authorize(tryon, authorization)
    compression = request.options.compression
    outfit_id, result, cached = await tryon.outfit(request.spec(), compression)
    url = signed_url(tryon, request, kid)
    if glb:
        data = result.encoded(compression)
        return glb_answer(data, outfit_id, compression, IMMUTABLE, **{"Content-Location": url})
    return OutfitCreated(id=outfit_id, glb_url=url, cached=cached, report=result.report)


def _param(name: str, schema: dict, description: str, required: bool = False) -> dict:
    return {"name": name, "in": "query", "required": required, "schema": schema, "description": description}


ITEM = f"{GARMENT_ID}(:({'|'.join(LETTERS)}))?"
# Parsed by ``outfit_url.parse_query`` (one model, the POST's), declared here for clients and fuzzers.
QUERY_PARAMETERS = [
    _param("garments", {"type": "string", "pattern": f"^{ITEM}(,{ITEM})*$"},
           "Garments, inner to outer, comma-separated, each `id` or `id:SIZE` (the POST's `garments`: "
           "`tshirt:L` is `{\"id\": \"tshirt\", \"size\": \"L\"}`).", required=True),
    _param("gender", {"type": "number", "minimum": 0, "maximum": 1}, "The POST's `body.gender`."),
    _param("height_cm", {"type": "number"}, "The POST's `body.height_cm`."),
    _param("weight_kg", {"type": "number"}, "The POST's `body.weight_kg`."),
    *(_param(name, {"type": "number", "exclusiveMinimum": 0},
             f"The POST's `body.{name}` (absent: predicted).") for name in GIRTH_FIELDS),
    _param("untangle", {"type": "boolean"}, "The POST's `options.untangle`."),
    _param("include_body", {"type": "boolean"}, "The POST's `options.include_body`."),
    _param("untangler", {"type": "string", "enum": ["neural", "reference"]},
           "The POST's `options.untangler`."),
    _param("compression", {"type": "string", "enum": ["none", "quantized", "meshopt"]},
           "The POST's `options.compression`."),
    _param("tension", {"type": "boolean"}, "The POST's `options.tension`."),
    _param("v", {"type": "string"}, "Model version the URL was made for; another (or none): served by the "
           "serving models with `Cache-Control: public, no-cache`."),
    _param("k", {"type": "string"}, "API key id of a signed URL."),
    _param("sig", {"type": "string"}, "Signature of a signed URL (POST /v1/outfits makes it)."),
]  # fmt: skip


@router.get(
    outfit_url.PATH.removeprefix("/v1"),
    response_class=Response,
    responses={200: {"content": GLB_CONTENT, "description": "The outfit's GLB (`ETag`: the outfit id; "
                     "immutable when `v` is the serving model version)."},
               304: {"description": "`If-None-Match` names this outfit's ETag."},
               **{k: v for k, v in ERRORS.items() if k not in (413, 415)}},  # fmt: skip
    openapi_extra={"parameters": QUERY_PARAMETERS},
)
async def get_outfit_by_url(
    http: Request, tryon: TryOnDep, if_none_match: Annotated[str | None, Header()] = None,
    authorization: Annotated[str | None, Header()] = None,
) -> Response:  # fmt: skip
    """The GLB of the outfit the query describes, from any replica: made here (the same bytes as
    anywhere else) when this replica has not made it yet."""
    query = outfit_url.parse_query(list(http.query_params.multi_items()))
    spec, compression = query.request.spec(), query.request.options.compression
    version = tryon.require_engine().model_version
    authorize(tryon, authorization, signed_by(tryon, query))
    outfit_id = spec.outfit_id(version)
    cache_control = IMMUTABLE if query.version == version else REVALIDATE
    tag = etag(outfit_id, compression)
    headers = {"ETag": tag, "Cache-Control": cache_control, "X-Outfit-Id": outfit_id}
    if if_none_match is not None and matches(if_none_match, tag):
        return Response(status_code=304, headers=headers)
    outfit_id, result, _ = await tryon.outfit(spec, compression)
    return glb_answer(result.encoded(compression), outfit_id, compression, cache_control)


@router.get(
    "/outfits/{outfit_id}.glb",
    response_class=Response,
    responses={200: {"content": GLB_CONTENT, "description": "The outfit's plain GLB."},
               404: {"model": ErrorResponse, "description": "Not in this replica's cache: use `glb_url`."},
               422: ERRORS[422]},  # fmt: skip
)
def get_outfit_glb(
    outfit_id: Annotated[str, Path(pattern=OUTFIT_ID, description="`id` from POST /v1/outfits.")],
    tryon: TryOnDep, authorization: Annotated[str | None, Header()] = None,
) -> Response:
    """The plain GLB of an outfit this replica made recently, by id (kept for existing clients). Only
    the replica that made it has it, until its cache evicts it; `glb_url` works on every replica."""
    authorize(tryon, authorization)
    data = tryon.cached_glb(outfit_id)
    if data is None:
        detail = (f"outfit {outfit_id} is not in this replica's cache (evicted, made elsewhere, or never "
                  "made): GET the `glb_url` of POST /v1/outfits instead")  # fmt: skip
        raise HTTPException(404, detail=detail)
    return glb_answer(data, outfit_id, "none", IMMUTABLE)
