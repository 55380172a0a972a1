"""Builds the HTTP app: routes (``service.server.routes``), error answers, middleware, start-up and
shutdown."""

from __future__ import annotations

import asyncio
import signal
import threading
from contextlib import asynccontextmanager
from importlib.metadata import PackageNotFoundError, version

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.routing import APIRoute

from service.server import errors, logs
from service.server.middleware import AccessLog, BodyLimit, GzipJson
from service.server.routes import admin, bodies, body, fit, garments, outfits, page, probes
from service.server.routes.garments import CATALOG_NOT_LOADED, try_load_catalog
from service.server.runtime import EngineFactory, TryOn, load_engine
from service.server.settings import Settings

__all__ = ["CATALOG_NOT_LOADED", "create_app", "try_load_catalog"]



def _reload_on_sighup(tryon: TryOn) -> None:
    """``kill -HUP`` reloads the models on a thread (where the loop can take signals: not in tests)."""
    try:
        loop = asyncio.get_running_loop()
        loop.add_signal_handler(signal.SIGHUP, lambda: threading.Thread(target=tryon.reload_logged).start())
    except (NotImplementedError, RuntimeError, ValueError, AttributeError):
        pass


def package_version() -> str:
    try:
        return version("ulnef")
    except PackageNotFoundError:  # running from a source tree that was never installed
        return "0.0.0"


def operation_id(route: APIRoute) -> str:
    """Operation ids are the route functions' names (``list_garments``), for generated clients."""
    return route.name


def create_app(settings: Settings | None = None, engine_factory: EngineFactory = load_engine) -> FastAPI:
    """The app; models load when it starts (lifespan), and a models directory that differs from its
    manifest makes start-up fail (``service.server.runtime.ModelIntegrityError``)."""
    settings = settings if settings is not None else Settings()
    tryon = TryOn(settings, engine_factory)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        if settings.configure_logging:
            logs.configure(settings.log_level, settings.log_format)
        tryon.start()
        _reload_on_sighup(tryon)
        yield
        tryon.stop()

    app = FastAPI(
        title="ULNeF try-on service",
        version=package_version(),
        generate_unique_id_function=operation_id,
        lifespan=lifespan,
        # Swagger UI and ReDoc load their scripts from a CDN; the page and /openapi.yaml need none.
        docs_url=None,
        redoc_url=None,
    )
    app.state.settings = settings
    app.state.tryon = tryon

    def garment_ids() -> list[str]:
        if tryon.engine is not None:
            return tryon.engine.garment_ids()
        catalog = try_load_catalog(settings)
        return list(catalog) if catalog else []

    errors.install(app, garment_ids)
    # Added innermost first: the access log sees every answer, the size limit's 413 included.
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware, allow_origins=settings.cors_origins, allow_methods=["GET", "POST"],
            allow_headers=["Content-Type", "Accept", "Authorization", "If-None-Match"],
            expose_headers=["X-Outfit-Id", "X-Body-Id", "Content-Location", "ETag", "Retry-After"],
        )  # fmt: skip
    app.add_middleware(GzipJson)
    app.add_middleware(BodyLimit, max_bytes=settings.max_body_bytes)
    app.add_middleware(AccessLog, metrics=tryon.metrics)
    app.include_router(probes.router)
    app.include_router(garments.router)
    app.include_router(outfits.router)
    app.include_router(bodies.router)
    app.include_router(fit.router)
    app.include_router(body.router)
    app.include_router(admin.router)
    app.include_router(page.router)
    app.mount("/static", page.static_files(), name="static")
    return app


# For `uvicorn service.server.app:app` (the container): settings from the environment; nothing loads
# until the server starts the app.
app = create_app()
