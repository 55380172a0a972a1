"""Shared pieces of the HTTP load, soak and memory benchmarks: a server on loopback, request mixes
over the catalog and the supported body range, an asyncio client, latency statistics and RSS.

Traffic only ever goes to loopback (127.0.0.0/8, ::1, localhost): ``check_loopback`` refuses
anything else. Every loop is bounded in request count and in time.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import os
import socket
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import numpy as np

from service.pipeline.body import BodyModel, supported_height_range_cm, supported_weight_range_kg

REPO_ROOT = Path(__file__).resolve().parents[1]
GLB_MEDIA_TYPE = "model/gltf-binary"
# Keep sampled shapes this far inside the supported range (cm, kg) so rounding never leaves it.
RANGE_MARGIN = 0.5
MAX_GARMENTS = 4


def check_loopback(url: str) -> str:
    """``url`` without a trailing slash; ValueError unless its host is a loopback address."""
    host = urlsplit(url).hostname or ""
    loopback = host == "localhost"
    with contextlib.suppress(ValueError):
        loopback = loopback or ipaddress.ip_address(host).is_loopback
    if not loopback:
        raise ValueError(f"refusing to load {url!r}: only loopback targets (127.0.0.1, ::1, localhost)")
    return url.rstrip("/")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class LocalServer:
    """``ulnef serve`` on 127.0.0.1 in a child process, with extra ``ULNEF_*`` environment."""

    env: dict[str, str] = field(default_factory=dict)
    ready_timeout_s: float = 300.0
    port: int = field(default_factory=free_port)
    process: subprocess.Popen | None = None
    startup_s: float = float("nan")

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def __enter__(self) -> LocalServer:
        cmd = [sys.executable, "-m", "service.cli", "serve", "--host", "127.0.0.1", "--port", str(self.port)]
        env = {**os.environ, "ULNEF_LOG_LEVEL": "warning", **self.env}
        t0 = time.perf_counter()
        self.process = subprocess.Popen(cmd, cwd=REPO_ROOT, env=env)
        deadline = t0 + self.ready_timeout_s
        while time.perf_counter() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"server exited with status {self.process.returncode} before /readyz")
            with contextlib.suppress(httpx.HTTPError):
                if httpx.get(f"{self.url}/readyz", timeout=5).status_code == 200:
                    self.startup_s = time.perf_counter() - t0
                    return self
            time.sleep(0.5)
        self.__exit__()
        raise TimeoutError(f"/readyz not 200 within {self.ready_timeout_s:g} s")

    def __exit__(self, *exc) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


def _proc_tree(pid: int) -> Iterator[int]:
    yield pid
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:  # a thread can end between the listing and the read (the body map's short-lived pool)
            children = (task / "children").read_text().split()
        except (FileNotFoundError, ProcessLookupError):
            continue
        for child in children:
            yield from _proc_tree(int(child))


def _status_kb(pid: int, key: str) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1])
    return 0


def rss_mb(pid: int) -> tuple[float, float]:
    """(current RSS, peak RSS) in MB (10^6 bytes) of process ``pid`` and its descendants (Linux /proc)."""
    pids = list(_proc_tree(pid))
    rss = sum(_status_kb(p, "VmRSS") for p in pids)
    hwm = sum(_status_kb(p, "VmHWM") for p in pids)
    return rss * 1024 / 1e6, hwm * 1024 / 1e6


# ---------------------------------------------------------------- request mixes


@dataclass(frozen=True)
class Catalog:
    """Garment ids from GET /v1/garments: tops in stacking order (inner first), bottoms."""

    tops: tuple[str, ...]
    bottoms: tuple[str, ...]

    @classmethod
    def from_listing(cls, listing: dict) -> Catalog:
        rows = listing["garments"]
        tops = sorted((g for g in rows if g["category"] == "top"), key=lambda g: g["layer_rank"])
        return cls(tuple(g["id"] for g in tops), tuple(g["id"] for g in rows if g["category"] == "bottom"))

    def random_outfit(self, rng: np.random.Generator, n: int) -> list[str]:
        """``n`` distinct garments inner to outer: tops in stacking order, at most one bottom, put
        at a random place among them (under the tops = tucked in, over them = not)."""
        if not 1 <= n <= min(MAX_GARMENTS, len(self.tops) + min(1, len(self.bottoms))):
            raise ValueError(f"cannot make an outfit of {n} garments from {self}")
        n_bottoms = 1 if n > len(self.tops) else int(self.bottoms != () and rng.random() < 0.5)
        picked = sorted(rng.choice(len(self.tops), n - n_bottoms, replace=False))
        outfit = [self.tops[i] for i in picked]
        if n_bottoms:
            outfit.insert(int(rng.integers(0, len(outfit) + 1)), str(rng.choice(self.bottoms)))
        return outfit


def random_body(rng: np.random.Generator, body: BodyModel) -> dict[str, float]:
    """Uniform gender, then height and weight uniform inside the range supported for it
    (service.pipeline.body)."""
    gender = round(float(rng.uniform(0.0, 1.0)), 3)
    h_lo, h_hi = supported_height_range_cm(body, gender)
    height = round(float(rng.uniform(h_lo + RANGE_MARGIN, h_hi - RANGE_MARGIN)), 1)
    w_lo, w_hi = supported_weight_range_kg(body, gender, height)
    weight = round(float(rng.uniform(w_lo + RANGE_MARGIN, w_hi - RANGE_MARGIN)), 1)
    return {"gender": gender, "height_cm": height, "weight_kg": weight}


def outfit_request(garments: Sequence[str], body: dict[str, float]) -> dict:
    return {"garments": list(garments), "body": body, "options": {"untangle": True, "include_body": True}}


def make_requests(
    rng: np.random.Generator, catalog: Catalog, body: BodyModel, count: int, sizes: Sequence[int]
) -> list[dict]:
    """``count`` requests, each a fresh body shape (cold: nothing to reuse); sizes cycle through ``sizes``."""
    return [outfit_request(catalog.random_outfit(rng, sizes[i % len(sizes)]), random_body(rng, body))
            for i in range(count)]  # fmt: skip


# ---------------------------------------------------------------- client and statistics


# Answers that mean "overloaded or out of time, retry later" (with Retry-After), not a fault.
REJECTED = frozenset({429, 503, 504})
MAX_BACKOFF_S = 5.0


@dataclass(frozen=True)
class Result:
    n_garments: int
    seconds: float
    status: int  # HTTP status; 0 when no answer came (timeout, connection error)
    cached: bool | None = None
    error: str | None = None
    retry_after_s: float | None = None

    @property
    def rejected(self) -> bool:
        return self.status in REJECTED


async def back_off(result: Result) -> None:
    """A polite client: after a rejection, wait what Retry-After says (at most MAX_BACKOFF_S)."""
    if result.rejected:
        await asyncio.sleep(min(result.retry_after_s or 1.0, MAX_BACKOFF_S))


async def post_outfit(client: httpx.AsyncClient, url: str, request: dict, glb: bool) -> Result:
    headers = {"Accept": GLB_MEDIA_TYPE if glb else "application/json"}
    n = len(request["garments"])
    t0 = time.perf_counter()
    try:
        response = await client.post(f"{url}/v1/outfits", json=request, headers=headers)
    except httpx.HTTPError as e:
        return Result(n, time.perf_counter() - t0, 0, error=type(e).__name__)
    seconds = time.perf_counter() - t0
    if response.status_code != 200:
        retry = response.headers.get("Retry-After", "")
        retry_s = float(retry) if retry.replace(".", "", 1).isdigit() else None
        return Result(n, seconds, response.status_code, error=response.text[:200], retry_after_s=retry_s)
    if glb:
        ok = response.content[:4] == b"glTF"
        return Result(n, seconds, 200 if ok else -1, error=None if ok else "answer is not a GLB")
    return Result(n, seconds, 200, cached=response.json().get("cached"))


async def run_requests(
    url: str, requests: Sequence[dict], concurrency: int, max_seconds: float, timeout_s: float, glb: bool
) -> tuple[list[Result], float]:
    """Send ``requests`` in order from ``concurrency`` clients; none is started after ``max_seconds``.
    Returns the results and the wall time."""
    queue = list(reversed(requests))
    results: list[Result] = []
    t0 = time.perf_counter()

    async def client_loop(client: httpx.AsyncClient) -> None:
        while queue and time.perf_counter() - t0 < max_seconds:
            results.append(await post_outfit(client, url, queue.pop(), glb))
            await back_off(results[-1])

    limits = httpx.Limits(max_connections=concurrency)
    async with httpx.AsyncClient(timeout=timeout_s, limits=limits) as client:
        await asyncio.gather(*(client_loop(client) for _ in range(concurrency)))
    return results, time.perf_counter() - t0


@dataclass(frozen=True)
class Stats:
    sent: int
    ok: int
    rejected: int  # 429/503/504: overload or deadline, answered with Retry-After
    errors: int  # every other failure: 4xx/5xx, no answer, not a GLB
    p50_ms: float
    p95_ms: float
    p99_ms: float
    throughput: float  # successful requests per second of wall time
    statuses: str  # "503x2, 0x1" for the failures

    @classmethod
    def of(cls, results: Sequence[Result], wall_s: float) -> Stats:
        ok = [r.seconds * 1e3 for r in results if r.status == 200]
        p50, p95, p99 = np.percentile(ok, (50, 95, 99)) if ok else (float("nan"),) * 3
        failed = Counter(r.status for r in results if r.status != 200)
        statuses = ", ".join(f"{s}x{n}" for s, n in sorted(failed.items()))
        rejected = sum(r.rejected for r in results)
        return cls(len(results), len(ok), rejected, len(results) - len(ok) - rejected,
                   float(p50), float(p95), float(p99), len(ok) / wall_s if wall_s > 0 else float("nan"),
                   statuses)  # fmt: skip


def format_table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """Markdown table; floats with one decimal, or three significant digits below 1 (0.0512 req/s)."""

    def cell(c: object) -> str:
        if isinstance(c, float):
            return f"{c:.3g}" if abs(c) < 1 else f"{c:.1f}"
        return str(c)

    cells = [[cell(c) for c in row] for row in rows]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in cells])


def fetch_catalog(url: str) -> Catalog:
    response = httpx.get(f"{url}/v1/garments", timeout=30)
    response.raise_for_status()
    return Catalog.from_listing(response.json())
