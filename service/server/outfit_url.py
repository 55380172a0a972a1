"""GLB URLs that carry their request: ``/v1/outfits.glb?garments=pants,tshirt&height_cm=180&...&v=VER``.

Any replica can answer such a URL, including one that never saw the POST: it parses the query into
the same ``OutfitRequest`` the POST validates (same rules, same ``allowed`` texts), computes the outfit
(deterministic: the same bytes on every replica of a model version) and caches it. ``v`` is the model
version the URL was made for; the bytes behind a URL with the serving ``v`` never change, so it is
cached as immutable. A URL whose ``v`` is absent or another version's (a rolling update) is answered
with the serving models, revalidated by ETag instead of cached for ever: redirecting between
replicas of different versions could loop.

With API keys on, ``k`` (the key's id) and ``sig`` (an HMAC of the rest under ``ULNEF_URL_SECRET_FILE``)
let a viewer that cannot send ``Authorization`` (``<model-viewer src=...>``) fetch the GLB; the
request counts against key ``k``'s rate limit (``service.server.access``).

Query parameters: the POST's fields by their last name (``height_cm``, not ``body.height_cm``);
``garments`` comma-separated, each ``id`` or ``id:SIZE`` (``tshirt:L``), booleans ``true``/``false``.
Defaults are left out of the URLs made here, and so are the girths not given (``chest_cm``,
``waist_cm``, ``hip_cm``: predicted).

A body alone (POST /v1/bodies) has the same kind of URL, ``/v1/bodies.glb?height_cm=165&...&v=VER``
(``BODIES``): the body's fields and ``compression`` only. Its signature covers the same canonical text,
which names no garment: no outfit's URL (one garment or more) can carry a body's signature.
"""

from __future__ import annotations

import hmac
from dataclasses import dataclass
from hashlib import sha256
from urllib.parse import urlencode

from pydantic import BaseModel, ValidationError

from service.pipeline.tryon import GIRTH_FIELDS, OutfitSpec
from service.server.schemas import BodyRequest, OutfitOptions, OutfitRequest

PATH = "/v1/outfits.glb"
BODY_PATH = "/v1/bodies.glb"
BODY_NUMBERS = ("gender", "height_cm", "weight_kg", *GIRTH_FIELDS)
# query parameter -> the POST field it stands for (its ``ALLOWED`` entry and its place in the body)
BODY_FIELDS = {name: f"body.{name}" for name in BODY_NUMBERS} | {"compression": "options.compression"}
FIELDS = {
    "garments": "garments",
    **{name: f"body.{name}" for name in BODY_NUMBERS},
    "untangle": "options.untangle",
    "include_body": "options.include_body",
    "untangler": "options.untangler",
    "compression": "options.compression",
    "tension": "options.tension",
}
NUMBERS = set(BODY_NUMBERS)
BOOLEANS = {"untangle", "include_body", "tension"}
EXTRA = ("v", "k", "sig")  # model version, API key id, signature
OPTION_DEFAULTS = OutfitOptions()


@dataclass(frozen=True)
class UrlKind:
    """What a GLB URL path carries: its query parameters (``FIELDS``) and the POST model they make."""

    path: str
    fields: dict[str, str]
    model: type[BaseModel]


OUTFITS = UrlKind(PATH, FIELDS, OutfitRequest)
BODIES = UrlKind(BODY_PATH, BODY_FIELDS, BodyRequest)


class QueryInvalid(ValueError):
    """Query parameters that do not make an outfit request. ``errors`` are pydantic-style dicts
    (``loc``, ``type``, ``msg``) with the POST's locations (``("body", "body", "height_cm")``), so the
    HTTP answer names the same fields with the same messages as the POST's (``service.server.errors``);
    a parameter the POST has no field for is ``("query", name)``."""

    def __init__(self, errors: list[dict]):
        super().__init__("; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in errors))
        self.errors = errors


@dataclass(frozen=True)
class GlbQuery:
    """A parsed GLB URL: the request, and the URL's model version, key id and signature (or None)."""

    request: OutfitRequest | BodyRequest
    version: str | None
    key_id: str | None
    sig: str | None


def _number(text: str) -> str:
    """Shortest text that parses back to the same float (``180`` for 180.0)."""
    text = repr(float(text))
    return text[:-2] if text.endswith(".0") else text


def _body_items(spec: OutfitSpec) -> list[tuple[str, str]]:
    """The body's numbers, girths only when given."""
    values = ((name, getattr(spec, name)) for name in BODY_NUMBERS)
    return [(name, _number(value)) for name, value in values if value is not None]


def body_query(spec: OutfitSpec, compression: str, version: str) -> list[tuple[str, str]]:
    """Canonical query of the body of ``spec`` (``BODIES``), without key id and signature."""
    items = _body_items(spec)
    if compression != OPTION_DEFAULTS.compression:
        items.append(("compression", compression))
    return [*items, ("v", version)]


def glb_query(spec: OutfitSpec, compression: str, version: str) -> list[tuple[str, str]]:
    """Canonical query of ``spec`` (defaults left out), without key id and signature."""
    garments = [g if (s := spec.size_of(k)) is None else f"{g}:{s}" for k, g in enumerate(spec.garments)]
    items = [("garments", ",".join(garments)), *_body_items(spec)]
    for name in ("untangle", "include_body", "tension"):
        if getattr(spec, name) != getattr(OPTION_DEFAULTS, name):
            items.append((name, "true" if getattr(spec, name) else "false"))
    if spec.untangler != OPTION_DEFAULTS.untangler:
        items.append(("untangler", spec.untangler))
    if compression != OPTION_DEFAULTS.compression:
        items.append(("compression", compression))
    return [*items, ("v", version)]


def signature(secret: bytes, key_id: str, spec: OutfitSpec, compression: str, version: str) -> str:
    """32 hex chars binding key id, model version, compression and the canonical request; the order or
    spelling of the query does not change it."""
    text = f"{key_id}\n{version}\n{compression}\n{spec.canonical_json()}".encode()
    return hmac.new(secret, text, sha256).hexdigest()[:32]


def glb_url(spec: OutfitSpec, compression: str, version: str, key_id: str | None = None,
            secret: bytes | None = None, kind: UrlKind = OUTFITS) -> str:  # fmt: skip
    """The GLB URL of an outfit (or, ``kind=BODIES``, of a body: ``spec`` without garments), signed
    for ``key_id`` when a secret is given."""
    items = (body_query if kind is BODIES else glb_query)(spec, compression, version)
    if key_id is not None and secret is not None:
        items += [("k", key_id), ("sig", signature(secret, key_id, spec, compression, version))]
    return f"{kind.path}?{urlencode(items, safe=',:')}"


def _error(name: str, message: str, kind: str = "value_error") -> dict:
    return {"loc": ("query", name), "type": kind, "msg": message}


def _garment_item(text: str):
    """``id`` -> the id, ``id:SIZE`` -> ``{"id", "size"}``, as the POST's ``garments`` items."""
    gid, colon, size = text.partition(":")
    return {"id": gid, "size": size} if colon else gid


def _value(name: str, text: str):
    """Query text -> the JSON value the POST would carry. Text that is no number (or no boolean) is
    passed on as text, so the POST's strict validation refuses it with the POST's message."""
    if name == "garments":
        return [_garment_item(t) for t in text.split(",")] if text else []
    if name in NUMBERS:
        try:
            return float(text)
        except ValueError:
            return text
    if name in BOOLEANS and text in ("true", "false"):
        return text == "true"
    return text


def parse_query(items: list[tuple[str, str]], kind: UrlKind = OUTFITS) -> GlbQuery:
    """``[(name, value)]`` of a GLB URL of ``kind`` -> ``GlbQuery``; raises ``QueryInvalid`` naming
    every bad parameter (unknown, repeated, malformed, or refused by the POST's own validation)."""
    errors, seen, body = [], set(), {"body": {}, "options": {}}
    extra: dict[str, str] = {}
    for name, text in items:
        if name in seen:  # the POST cannot say this: named as the query parameter
            errors.append(_error(name, "given more than once"))
            continue
        seen.add(name)
        if name in EXTRA:
            extra[name] = text
            continue
        if name not in kind.fields:
            errors.append(_error(name, "unknown field", "extra_forbidden"))
            continue
        value = _value(name, text)
        part, _, leaf = kind.fields[name].rpartition(".")
        if part:
            body[part][leaf] = value
        else:
            body[leaf] = value
    if errors:
        raise QueryInvalid(errors)
    try:
        request = kind.model.model_validate(body)
    except ValidationError as e:
        raise QueryInvalid([d | {"loc": ("body", *d["loc"])} for d in e.errors()]) from None
    return GlbQuery(request, extra.get("v"), extra.get("k"), extra.get("sig"))


def message(error: dict) -> str:
    """pydantic's message without its "Value error, " prefix (our own validators' text)."""
    if error.get("type") == "value_error" and "error" in error.get("ctx", {}):
        return str(error["ctx"]["error"])
    return str(error.get("msg", "invalid"))
