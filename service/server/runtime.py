"""The service's long-lived state: models, readiness, worker pool, cache, metrics.

Start-up (``TryOn.start``) first checks every model file against ``models/manifest.json`` and
refuses to start on any difference (``ModelIntegrityError``); the models are then loaded and a
self-test outfit made on a background thread, and ``ready`` turns true only when both succeeded.
"""

from __future__ import annotations

import asyncio
import hashlib
import logging
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import replace
from pathlib import Path

from service.pipeline.catalog import load_catalog, verified_imports
from service.pipeline.tryon import (
    GIRTH_FIELDS,
    Engine,
    ModelEngine,
    OutfitResult,
    OutfitSpec,
    RefusedOrder,
    self_test,
)
from service.process.manifest import MANIFEST_NAME, REFRESH_COMMAND, verify_manifest
from service.server.access import ApiKeys, KeysFileError, RateLimiter, read_digests
from service.server.cache import OutfitCache
from service.server.metrics import Metrics
from service.server.settings import Settings
from service.server.worker import BoundedWorker, DeadlineExceeded, Overloaded

log = logging.getLogger(__name__)
EngineFactory = Callable[[Settings], Engine]
Make = Callable[[OutfitSpec], OutfitResult]
NOT_LOADED = "models not loaded yet"


def body_spec(spec: OutfitSpec) -> OutfitSpec:
    """The body of ``spec`` alone: no garments, default options."""
    return OutfitSpec((), **{name: getattr(spec, name) for name in ("gender", "height_cm", "weight_kg",
                                                                     *GIRTH_FIELDS)})  # fmt: skip


def body_id(spec: OutfitSpec, version: str) -> str:
    """32 hex chars naming the body of ``spec`` (its garments and options ignored) on these models: the
    cache key of a body alone (POST /v1/bodies), never an outfit's (``OutfitSpec.outfit_id``)."""
    text = f"{version}\nbody\n{body_spec(spec).canonical_json()}"
    return hashlib.sha256(text.encode()).hexdigest()[:32]


class ModelIntegrityError(RuntimeError):
    """The models directory does not match its manifest."""


class ReloadBusy(Exception):
    """Another reload is running."""


class NotReady(Exception):
    """Models not loaded, or the self-test has not passed (``detail`` says which)."""


def check_models(settings: Settings) -> None:
    """Raise ``ModelIntegrityError`` listing every file that differs from the manifest."""
    directory = settings.resolved_models_dir()
    problems = verify_manifest(directory)
    if problems:
        listing = "\n".join(f"  - {p}" for p in problems)
        raise ModelIntegrityError(
            f"refusing to start: {directory} does not match its {MANIFEST_NAME} "
            f"({len(problems)} problem(s)):\n{listing}\n"
            f"restore the files (git checkout models/), or rebuild with `make models` / `{REFRESH_COMMAND}`"
        )


def load_engine(settings: Settings) -> Engine:
    """The models, and the imported garments whose files match their manifests (the others are
    logged and left out: a half-copied import must not take the service down)."""
    imported, broken = verified_imports(settings.garments_dir)
    for gid, problems in broken.items():
        log.error("imported garment %s left out: %s", gid, "; ".join(problems))
    return ModelEngine.load(settings.resolved_models_dir(), settings.onnx_threads, imported)


def read_access(settings: Settings) -> tuple[ApiKeys | None, bytes | None]:
    """The API keys and the URL signing secret the settings name (None: off); raises ``KeysFileError``."""
    if settings.api_keys_file is None:
        return None, None
    keys = ApiKeys(read_digests(settings.api_keys_file))
    if settings.url_secret_file is None:
        return keys, None
    try:
        secret = Path(settings.url_secret_file).read_bytes().strip()
    except OSError as e:
        raise KeysFileError(f"URL secret file {settings.url_secret_file}: {e}") from None
    if len(secret) < 16:
        raise KeysFileError(f"URL secret file {settings.url_secret_file}: at least 16 bytes needed")
    return keys, secret


class TryOn:
    def __init__(self, settings: Settings, engine_factory: EngineFactory = load_engine):
        self.settings = settings
        self.engine_factory = engine_factory
        self.engine: Engine | None = None
        self.ready = False
        self.detail = NOT_LOADED
        self.metrics = Metrics()
        self.cache = OutfitCache(settings.cache_entries, settings.cache_bytes)
        self.worker = BoundedWorker(settings.workers, settings.queue_size)
        self._inflight: dict[str, Future[OutfitResult]] = {}
        self._inflight_lock = threading.Lock()
        self._loader: threading.Thread | None = None
        self._reloading = threading.Lock()
        self.keys, self.url_secret = read_access(settings)
        self.limiter = RateLimiter(settings.rate_limit_per_minute, settings.rate_limit_burst)

    # ------------------------------------------------------------ start-up

    def start(self) -> None:
        """Integrity check now (raises), then load and self-test in the background."""
        if self.settings.verify_models:
            check_models(self.settings)
        self._loader = threading.Thread(target=self._load, name="model-loader", daemon=True)
        self._loader.start()

    def _load(self) -> None:
        t0 = time.perf_counter()
        try:
            engine = self.engine_factory(self.settings)
            self.detail = "self-test outfit running"
            self.engine = engine
            garments = self.settings.self_test_garments
            if garments:
                result = self_test(engine, garments, self.settings.self_test_untangle)
                self.metrics.observe_stages(result.report.get("seconds", {}))
        except Exception as e:  # anything at all: stay up, unready, and say why
            self.detail = f"start-up failed: {type(e).__name__}: {e}"
            log.exception("model loading or self-test failed")
            return
        self.ready, self.detail = True, "ok"
        self.metrics.ready.set(1)
        log.info("ready in %.1f s (model version %s)", time.perf_counter() - t0, engine.model_version)

    def reload(self) -> dict:
        """Load the models and the verified imports again (a new import appears), self-test the new
        engine, then swap it in; requests already running finish on the engine they started with,
        and outfits of the old model version stay in the cache under their ids. Raises
        ``ReloadBusy`` while another reload runs; any failure leaves the serving engine as it was."""
        if not self._reloading.acquire(blocking=False):
            raise ReloadBusy("a reload is already running")
        try:
            if self.settings.verify_models:
                check_models(self.settings)
            keys, secret = read_access(self.settings)  # keys added or revoked since the start
            load_catalog.cache_clear()  # a garment deleted and imported again under its id is new
            engine = self.engine_factory(self.settings)
            if self.settings.self_test_garments:
                self_test(engine, self.settings.self_test_garments, self.settings.self_test_untangle)
            before = set(self.engine.garment_ids()) if self.engine is not None else set()
            self.engine = engine
            self.keys, self.url_secret = keys, secret
            self.ready, self.detail = True, "ok"
            self.metrics.ready.set(1)
            after = set(engine.garment_ids())
            left_out = verified_imports(self.settings.garments_dir)[1]
            log.info("reloaded: model version %s, %d garments", engine.model_version, len(after))
            return {"model_version": engine.model_version, "garments": len(after),
                    "added": sorted(after - before), "removed": sorted(before - after),
                    "left_out": sorted(left_out)}  # fmt: skip
        finally:
            self._reloading.release()

    def reload_logged(self) -> None:
        """``reload`` for a signal handler: outcome logged, never raised."""
        try:
            self.reload()
        except Exception:  # a failed reload keeps serving what it served
            log.exception("reload failed; still serving the previous models")

    def wait_loaded(self, timeout: float) -> bool:
        """Block until the loader thread ended (tests); True when ready."""
        if self._loader is not None:
            self._loader.join(timeout)
        return self.ready

    def stop(self) -> None:
        self.worker.shutdown()

    # ------------------------------------------------------------ requests

    def require_engine(self) -> Engine:
        if not self.ready or self.engine is None:
            raise NotReady(self.detail)
        return self.engine

    def outfit_id(self, spec: OutfitSpec) -> str:
        return spec.outfit_id(self.require_engine().model_version)

    async def outfit(self, spec: OutfitSpec, compression: str = "none") -> tuple[str, OutfitResult, bool]:
        """(outfit id, result with its ``compression`` encoding written, whether it came from the cache).
        Raises NotReady, InvalidField, Overloaded, DeadlineExceeded."""
        engine = self.require_engine()
        return await self._serve(spec.outfit_id(engine.model_version), spec, engine, compression, engine.make,
                                 engine.validate)  # fmt: skip

    async def body(self, spec: OutfitSpec, compression: str = "none") -> tuple[str, OutfitResult, bool]:
        """``outfit`` for the body of ``spec`` alone (``Engine.make_body``), under its ``body_id``: the
        same cache, pool and time budget. Its ``InvalidField`` comes from the job (building the body is
        what checks it)."""
        engine, spec = self.require_engine(), body_spec(spec)
        return await self._serve(body_id(spec, engine.model_version), spec, engine, compression,
                                 engine.make_body, None)  # fmt: skip

    async def fit(self, spec: OutfitSpec, style: str) -> dict:
        """``Engine.fit`` in the pool, under the request's time budget (no cache: tens of ms).
        Raises NotReady, InvalidField, Overloaded, DeadlineExceeded."""
        engine = self.require_engine()
        timeout = self.settings.request_timeout_s
        future = self.worker.submit(lambda: engine.fit(spec, style), time.monotonic() + timeout)
        wrapped = asyncio.wrap_future(future)
        done, _ = await asyncio.wait({wrapped}, timeout=timeout)
        if not done:
            wrapped.add_done_callback(lambda f: f.cancelled() or f.exception())
            self.metrics.rejected.labels("deadline").inc()
            raise DeadlineExceeded(f"no fit within the {timeout:g} s time budget")
        return wrapped.result()

    async def _serve(
        self, key: str, spec: OutfitSpec, engine: Engine, compression: str, make: Make,
        validate: Callable[[OutfitSpec], None] | None,
    ) -> tuple[str, OutfitResult, bool]:  # fmt: skip
        try:
            key, result, cached = await self._outfit(key, spec, engine, compression, make, validate)
        except Overloaded:
            self.metrics.rejected.labels("overloaded").inc()
            raise
        if not result.has(compression):  # a cached outfit, or a shared job made for another encoding
            await asyncio.to_thread(result.encoded, compression)
            self.cache.put(key, result)  # counted again with its new encoding
        return key, result, cached

    async def _outfit(
        self, key: str, spec: OutfitSpec, engine: Engine, compression: str, make: Make,
        validate: Callable[[OutfitSpec], None] | None,
    ) -> tuple[str, OutfitResult, bool]:  # fmt: skip
        cached = self.cache.get(key)
        if cached is not None:
            self.metrics.cache.labels("hit").inc()
            return key, cached, True
        timeout = self.settings.request_timeout_s
        # A place in the pool before validating, so a full house is refused at once; validation runs
        # off the event loop (tens of ms for three garments), so other requests are answered meanwhile.
        reserved = key not in self._inflight
        if reserved:
            self.worker.reserve(time.monotonic() + timeout)
        try:
            try:
                if validate is not None:
                    await asyncio.to_thread(validate, spec)  # before counting a miss
            except RefusedOrder:
                self.metrics.rejected.labels("layer_order").inc()
                raise
            self.metrics.cache.labels("miss").inc()
            future = self._submit(key, spec, make, engine, compression, time.monotonic() + timeout, reserved)
            reserved = False  # the place is the job's now (or given back by a shared job)
        finally:
            if reserved:
                self.worker.release()
        # asyncio.wait, not wait_for: a timeout must not cancel a job other requests share.
        wrapped = asyncio.wrap_future(future)
        # A job that ends after its request gave up still ends with a result or an exception (dropped
        # unrun past its deadline): retrieve it, so asyncio does not log it as never retrieved.
        wrapped.add_done_callback(lambda f: f.cancelled() or f.exception())
        done, _ = await asyncio.wait({wrapped}, timeout=timeout)
        try:
            if not done:
                raise DeadlineExceeded(f"no outfit within the {timeout:g} s time budget")
            return key, wrapped.result(), False
        except DeadlineExceeded:
            self.metrics.rejected.labels("deadline").inc()
            raise

    def _submit(
        self, key: str, spec: OutfitSpec, make: Make, engine: Engine, compression: str, deadline: float,
        reserved: bool,
    ) -> Future[OutfitResult]:  # fmt: skip
        """One job per distinct outfit: identical concurrent requests share it (and give back the place
        they ``reserved``)."""
        with self._inflight_lock:
            future = self._inflight.get(key)
            if future is not None:
                if reserved:
                    self.worker.release()
                return future
            future = self.worker.submit(lambda: self._compute(key, spec, make, engine, compression), deadline,
                                        reserved)  # fmt: skip
            self._inflight[key] = future
            self._gauges()
        future.add_done_callback(lambda _: self._done(key))
        return future

    def _compute(
        self, key: str, spec: OutfitSpec, make: Make, engine: Engine, compression: str
    ) -> OutfitResult:
        self._gauges()
        result = make(spec)
        result.encoded(compression)
        self.metrics.observe_stages(result.report.get("seconds", {}))
        self.metrics.fallbacks.inc(len(result.report.get("numerical_fallback", [])))
        if result.report.get("collision_free") is False:
            self.metrics.with_crossings.inc()
        self.cache.put(key, result)
        if spec.measure:  # the same GLB as without measures: its URL (measure-free) finds it here
            self.cache.put(replace(spec, measure=False).outfit_id(engine.model_version), result)
        return result

    def _done(self, key: str) -> None:
        with self._inflight_lock:
            self._inflight.pop(key, None)
        self._gauges()

    def _gauges(self) -> None:
        self.metrics.queue_depth.set(self.worker.pending)
        self.metrics.running.set(self.worker.running)
        self.metrics.cache_entries.set(len(self.cache))
        self.metrics.cache_bytes.set(self.cache.nbytes)

    def cached_glb(self, outfit_id: str) -> bytes | None:
        """The plain GLB of a cached outfit (the id URL), or None."""
        item = self.cache.get(outfit_id)
        self.metrics.cache.labels("hit" if item else "miss").inc()
        return item.glb if item else None
