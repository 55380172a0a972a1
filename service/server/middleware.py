"""ASGI middleware: request size limit, one JSON log line plus metrics per request, gzip of JSON.

Pure ASGI (not ``BaseHTTPMiddleware``) so that an oversized body is refused before the app reads
it, whether the client sent Content-Length or streamed chunks.
"""

from __future__ import annotations

import gzip
import json
import logging
import time
import uuid

from service.server.metrics import Metrics

log = logging.getLogger("service.access")


async def _send_json(send, status: int, body: dict, headers: list[tuple[bytes, bytes]] = ()) -> None:
    data = json.dumps(body).encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"),
                            (b"content-length", str(len(data)).encode()), *headers]})  # fmt: skip
    await send({"type": "http.response.body", "body": data})


class BodyLimit:
    """Answer 413 to a request body over ``max_bytes``; smaller bodies are read here and replayed."""

    def __init__(self, app, max_bytes: int):
        self.app = app
        self.max_bytes = max_bytes

    def _too_large(self, send):
        message = "request body too large"
        allowed = f"at most {self.max_bytes} bytes (setting ULNEF_MAX_BODY_BYTES)"
        errors = [{"field": "(request body)", "message": message, "allowed": allowed}]
        return _send_json(send, 413, {"detail": f"{message}: {allowed}", "errors": errors})

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http" or scope["method"] in ("GET", "HEAD", "OPTIONS"):
            return await self.app(scope, receive, send)
        length = dict(scope["headers"]).get(b"content-length")
        if length is not None and (not length.isdigit() or int(length) > self.max_bytes):
            return await self._too_large(send)
        chunks, size, more = [], 0, True
        while more:
            message = await receive()
            if message["type"] == "http.disconnect":
                return
            chunk = message.get("body", b"")
            size += len(chunk)
            if size > self.max_bytes:
                return await self._too_large(send)
            chunks.append(chunk)
            more = message.get("more_body", False)
        body, replayed = b"".join(chunks), False

        async def replay():
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()  # after the body: wait for the disconnect, as the server would

        return await self.app(scope, replay, send)


class AccessLog:
    """Counts and times every request by route template (not raw path: bounded label set) and logs
    one structured line with a request id (echoed as ``X-Request-Id``)."""

    def __init__(self, app, metrics: Metrics):
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        request_id = uuid.uuid4().hex[:16]
        status = 500
        t0 = time.perf_counter()

        async def send_wrapper(message):
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
                message["headers"] = [*message.get("headers", []), (b"x-request-id", request_id.encode())]
            await send(message)

        try:
            await self.app(scope, receive, send_wrapper)
        finally:
            seconds = time.perf_counter() - t0
            route = scope.get("route")
            template = getattr(route, "path", None) or "unmatched"
            method = scope["method"]
            self.metrics.requests.labels(method, template, str(status)).inc()
            self.metrics.latency.labels(method, template).observe(seconds)
            log.info("request", extra={"fields": {
                "request_id": request_id, "method": method, "path": scope["path"], "route": template,
                "status": status, "ms": round(seconds * 1e3, 2),
                "client": (scope.get("client") or ("", 0))[0],
            }})  # fmt: skip


class GzipJson:
    """gzip JSON answers of at least ``min_bytes`` for clients that accept it. GLBs go out as they are:
    gzip takes a third off a plain GLB for 40-90 ms of a core (``benchmarks.glb_sizes --gzip``), a
    quarter of the outfit itself; a proxy in front (``deploy/nginx``) compresses them where it pays."""

    def __init__(self, app, min_bytes: int = 1024, level: int = 6):
        self.app = app
        self.min_bytes = min_bytes
        self.level = level

    async def __call__(self, scope, receive, send):
        accept = dict(scope.get("headers", ())).get(b"accept-encoding", b"")
        if scope["type"] != "http" or b"gzip" not in accept.lower():
            return await self.app(scope, receive, send)
        start: dict | None = None
        parts: list[bytes] = []

        async def wrapped(message):
            nonlocal start
            if message["type"] == "http.response.start":
                headers = dict(message.get("headers", ()))
                json_ = headers.get(b"content-type", b"").split(b";")[0].strip() == b"application/json"
                if json_ and b"content-encoding" not in headers:
                    start = message  # held until the whole body is here
                    return
            elif message["type"] == "http.response.body" and start is not None:
                parts.append(message.get("body", b""))
                if message.get("more_body", False):
                    return
                body = b"".join(parts)
                headers = [(k, v) for k, v in start.get("headers", ()) if k != b"content-length"]
                if len(body) >= self.min_bytes:
                    body = gzip.compress(body, self.level)
                    headers += [(b"content-encoding", b"gzip"), (b"vary", b"Accept-Encoding")]
                headers.append((b"content-length", str(len(body)).encode()))
                await send(start | {"headers": headers})
                message = {"type": "http.response.body", "body": body}
            await send(message)

        return await self.app(scope, receive, wrapped)
