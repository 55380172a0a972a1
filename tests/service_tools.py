"""Helpers for the HTTP tests: a fake engine, a live server in a thread or real `ulnef serve` processes,
external tools (node, chromium, nginx).

External tools skip their tests on a developer machine that lacks them, but fail them in CI
(``CI=true``), where `make test` installs them: a missing tool must not pass silently there.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import types
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
import uvicorn

from service.pipeline.catalog import Garment
from service.pipeline.gltf import GltfLayer, outfit_glb
from service.pipeline.sizes import LETTERS
from service.pipeline.tryon import (
    GIRTH_FIELDS,
    InvalidField,
    OutfitResult,
    OutfitSpec,
    check_garment_ids,
    check_sizes,
)

REPO = Path(__file__).resolve().parents[1]
JS_DIR = Path(__file__).parent / "js"
NODE_MODULES = JS_DIR / "node_modules"
CHROMIUM = os.environ.get("CHROMIUM", "/usr/bin/chromium")


def in_ci() -> bool:
    return os.environ.get("CI", "").lower() in ("1", "true", "yes")


def require(condition: bool, what: str) -> None:
    """Skip (developer machine) or fail (CI) when ``condition`` is false."""
    if condition:
        return
    message = f"{what} missing: run `make test` (it installs node packages, chromium and nginx)"
    if in_ci():
        pytest.fail(message)
    pytest.skip(message)


def require_node(*packages: str) -> str:
    node = shutil.which("node")
    require(node is not None, "node")
    for package in packages:
        require((NODE_MODULES / package).is_dir(), f"npm package {package} (tests/js/node_modules)")
    return node


def run_node(script: str, *args: str, timeout: float = 300, env: dict | None = None) -> str:
    node = require_node()
    proc = subprocess.run(
        [node, str(JS_DIR / script), *args], capture_output=True, text=True, timeout=timeout,
        cwd=JS_DIR, env={**os.environ, **(env or {})}, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, f"{script} failed ({proc.returncode}):\n{proc.stderr[-4000:]}"
    return proc.stdout


FAKE_HEIGHTS_CM = (135.0, 210.0)
FAKE_BMI = (13.0, 70.0)
# Fake girths at (height cm, weight kg): possible range lo = a h + b w, hi = c h + d w, and the value
# "predicted" when not given, e h + f w.
FAKE_GIRTHS = {"chest_cm": (0.3, 0.2, 0.4, 0.6, 0.35, 0.45), "waist_cm": (0.25, 0.15, 0.35, 0.6, 0.3, 0.35),
               "hip_cm": (0.3, 0.2, 0.4, 0.6, 0.4, 0.4)}  # fmt: skip
# A waist this much over the hip (both given) is a combination no fake body has.
FAKE_WAIST_OVER_HIP_CM = 30.0
FAKE_BODY = (np.array([[0, 0, 0], [0.2, 0, 0], [0, 0, 1.7], [0, 0.2, 0]], dtype=np.float64),
             np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]]))  # fmt: skip


def inwards(lo: float, hi: float) -> tuple[float, float]:
    """``(lo, hi)`` rounded inwards to 0.1, as the real refusals print bounds."""
    return math.ceil(round(lo * 10, 6)) / 10, math.floor(round(hi * 10, 6)) / 10


def fake_range(name: str, height_cm: float, weight_kg: float) -> tuple[float, float]:
    a, b, c, d, _, _ = FAKE_GIRTHS[name]
    return inwards(a * height_cm + b * weight_kg, c * height_cm + d * weight_kg)


# The fake's garments with sizes: the T-shirt in the letters (``check_sizes`` reads only ``letters``).
FAKE_SIZES = {"tshirt": types.SimpleNamespace(letters=LETTERS)}


class FakeEngine:
    """An ``Engine`` over a small catalog: the catalog's rest meshes on a dummy body, in
    ``delay`` seconds. Bodies follow the real rules with made-up numbers: heights 135-210 cm, BMI
    13-70, each girth within a range linear in height and weight (``FAKE_GIRTHS``; refused outside
    it with the real message), missing girths "predicted" likewise, and a waist 30 cm over the hip is
    a combination no body has.

    ``release``: each outfit waits until the test sets this event (a worker busy for exactly as long
    as the test wants, where a ``delay`` would race the machine's load); ``started`` is set when an
    outfit begins (the test then knows the worker is busy)."""

    model_version = "fake"

    def __init__(
        self, catalog: dict[str, Garment], delay: float = 0.0, nan: bool = False, crossings: int = 0,
        release: threading.Event | None = None,
    ):
        self.catalog = catalog
        self.delay = delay
        self.release = release
        self.started = threading.Event()
        self.nan = nan
        self.crossings = crossings  # crossing pairs the fake repair leaves
        self.calls = 0
        self._lock = threading.Lock()

    def garment_ids(self) -> list[str]:
        return list(self.catalog)

    def validate(self, spec: OutfitSpec) -> None:
        check_garment_ids(spec.garments, self.garment_ids(), 4)
        check_sizes(spec, FAKE_SIZES)
        self.body_report(spec)

    def body_report(self, spec: OutfitSpec) -> dict:
        """The fake body's ``report["body"]``; raises ``InvalidField`` as the real engine would."""
        h, w = spec.height_cm, spec.weight_kg
        if not FAKE_HEIGHTS_CM[0] <= h <= FAKE_HEIGHTS_CM[1]:
            raise InvalidField("body.height_cm", f"height_cm={h:g} is outside the supported range "
                               "135.0-210.0 cm", "135.0-210.0")  # fmt: skip
        w_lo, w_hi = inwards(*(bmi * (h / 100) ** 2 for bmi in FAKE_BMI))
        if not w_lo <= w <= w_hi:
            allowed = f"{w_lo:.1f}-{w_hi:.1f}"
            raise InvalidField("body.weight_kg", f"weight_kg={w:g} is outside the supported range {allowed} "
                               f"kg for height_cm={h:g} (BMI 13-70)", allowed)  # fmt: skip
        given = {name: getattr(spec, name) for name in GIRTH_FIELDS if getattr(spec, name) is not None}
        for name, value in given.items():
            lo, hi = fake_range(name, h, w)
            if not lo <= value <= hi:
                allowed = f"{lo:.1f}-{hi:.1f}"
                message = (f"{name}={value:g} is outside the range {allowed} cm that adults of "
                           f"height_cm={h:g} and weight_kg={w:g} have")  # fmt: skip
                raise InvalidField(f"body.{name}", message, allowed)
        waist, hip = given.get("waist_cm"), given.get("hip_cm")
        if waist is not None and hip is not None and waist > hip + FAKE_WAIST_OVER_HIP_CM:
            raise InvalidField("body.waist_cm", f"no body has waist_cm, hip_cm together as given (waist_cm="
                               f"{waist:g}, hip_cm={hip:g})", "a combination a body has")  # fmt: skip
        girths = {name: given.get(name, FAKE_GIRTHS[name][4] * h + FAKE_GIRTHS[name][5] * w)
                  for name in GIRTH_FIELDS}  # fmt: skip
        return {"height_cm": round(h, 1), "weight_kg": round(w, 1),
                **{name: round(value, 1) for name, value in girths.items()},
                "predicted": sorted(set(GIRTH_FIELDS) - set(given))}  # fmt: skip

    def body_ranges(self, gender: float, height_cm: float | None, weight_kg: float | None = None) -> dict:
        lo, hi = FAKE_HEIGHTS_CM
        h = (lo + hi) / 2 if height_cm is None else min(max(height_cm, lo), hi)
        w_lo, w_hi = inwards(*(bmi * (h / 100) ** 2 for bmi in FAKE_BMI))
        w = (w_lo + w_hi) / 2 if weight_kg is None else min(max(weight_kg, w_lo), w_hi)
        return {"height_cm": FAKE_HEIGHTS_CM, "weight_kg": (w_lo, w_hi), "at_height_cm": h, "at_weight_kg": w,
                **{name: fake_range(name, h, w) for name in GIRTH_FIELDS}}  # fmt: skip

    def _wait(self) -> None:
        with self._lock:
            self.calls += 1
        self.started.set()
        if self.release is not None:
            assert self.release.wait(60), "the test never released the fake engine"
        time.sleep(self.delay)

    def make_body(self, spec: OutfitSpec) -> OutfitResult:
        body = self.body_report(spec)
        self._wait()
        layers = [GltfLayer("body", *FAKE_BODY, extras={"body": body})]
        return OutfitResult(outfit_glb(layers), {"body": body}, layers)

    def make(self, spec: OutfitSpec) -> OutfitResult:
        body = self.body_report(spec)
        self._wait()
        layers = [(g, self.catalog[g].vertices, self.catalog[g].faces) for g in spec.garments]
        if spec.include_body:
            layers.insert(0, GltfLayer("body", *FAKE_BODY, extras={"body": body}))
        report = {"garments": list(spec.garments), "numerical_fallback": [],
                  "collision_free": self.crossings == 0, "crossing_pairs": self.crossings,
                  "seconds": {"body": 0.0, "total": self.delay}, "body": body}  # fmt: skip
        return OutfitResult(outfit_glb(layers), report, layers)


def wait_until(ready: Callable[[], bool], timeout: float, what: str | Callable[[], str],
               interval: float = 0.05) -> None:  # fmt: skip
    """Poll ``ready`` every ``interval`` s until it is true; fail the test after ``timeout`` s, saying
    ``what`` did not happen (a callable: called then, e.g. for a log's tail). For conditions that no
    event announces (another thread's or process's readiness); ``ready`` may itself fail the test
    early (a process that exited)."""
    deadline = time.monotonic() + timeout
    while not ready():
        if time.monotonic() > deadline:
            pytest.fail(f"not within {timeout:g} s: {what() if callable(what) else what}")
        time.sleep(interval)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def live_server(app, limit_concurrency: int | None = None, ready_timeout: float = 120) -> Iterator[str]:
    """Serve ``app`` with uvicorn on a free port in a thread; yields the base URL once /readyz is
    true (or fails the test after ``ready_timeout`` s)."""
    port = free_port()
    config = uvicorn.Config(app, host="127.0.0.1", port=port, log_config=None, log_level="warning",
                            limit_concurrency=limit_concurrency)  # fmt: skip
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        def started() -> bool:
            assert thread.is_alive(), "the server's thread ended before it started"
            return server.started

        wait_until(started, 30, "the server started")
        assert app.state.tryon.wait_loaded(ready_timeout), app.state.tryon.detail
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(30)


@contextmanager
def serve_processes(count: int, env: dict[str, str] | None = None, ready_timeout: float = 120,
                    log_dir: Path | None = None) -> Iterator[list[str]]:  # fmt: skip
    """``count`` real ``ulnef serve`` processes (the committed models) on free loopback ports, started
    at once, with the extra ``ULNEF_*`` settings ``env``; yields their base URLs once every /readyz
    is 200. Fails the test, quoting the process's log, when one exits or is not ready in time. The
    processes are always stopped (SIGTERM, then SIGKILL to their process group after 10 s)."""
    import httpx  # the serve extra's test client; only the tests that start servers need it

    log_dir = log_dir or Path(tempfile.mkdtemp(prefix="ulnef-serve-"))
    base = {**os.environ, "ULNEF_LOG_LEVEL": "warning", **(env or {})}
    procs: list[tuple[subprocess.Popen, str, Path]] = []
    try:
        for i in range(count):
            port, log = free_port(), log_dir / f"serve-{i}.log"
            cmd = [sys.executable, "-m", "service.cli", "serve", "--host", "127.0.0.1", "--port", str(port)]
            with log.open("wb") as out:
                proc = subprocess.Popen(cmd, cwd=REPO, env=base, stdout=out, stderr=subprocess.STDOUT,
                                        start_new_session=True)  # fmt: skip
            procs.append((proc, f"http://127.0.0.1:{port}", log))
        deadline = time.monotonic() + ready_timeout
        for proc, url, log in procs:

            def ready(proc=proc, url=url, log=log) -> bool:
                if proc.poll() is not None:
                    tail = log.read_text()[-3000:]
                    pytest.fail(f"ulnef serve at {url} exited ({proc.returncode}):\n{tail}")
                try:
                    return httpx.get(f"{url}/readyz", timeout=5).status_code == 200
                except httpx.HTTPError:
                    return False

            def what(url=url, log=log) -> str:
                return f"ulnef serve at {url}: /readyz 200:\n{log.read_text()[-3000:]}"

            wait_until(ready, max(deadline - time.monotonic(), 0.0), what, interval=0.2)
        yield [url for _, url, _ in procs]
    finally:
        for proc, _, _ in procs:
            stop_process_group(proc)


def stop_process_group(proc: subprocess.Popen, grace: float = 10) -> None:
    """SIGTERM ``proc`` (started with ``start_new_session=True``); after ``grace`` s SIGKILL its
    whole process group, so that no child it started outlives the test."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(grace)
        except subprocess.TimeoutExpired:
            pass
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
