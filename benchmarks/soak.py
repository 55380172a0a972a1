"""Soak test: mixed outfit load for N minutes while sampling the server's RSS; fails on growth.

Run (starts ``ulnef serve`` on a free 127.0.0.1 port, with a small outfit cache so that it fills
and evicts during the warm-up)::

    python -m benchmarks.soak [--minutes 10] [--concurrency 2] [--max-growth-mb 64]
    python -m benchmarks.soak --url http://127.0.0.1:8000 --pid PID     # a running server

The load is half cold requests (a new body shape each) and half repeats from a pool of earlier
ones, 1-4 garments (see benchmarks.load); after a 429/503/504 a client waits what Retry-After says
(at most 5 s). RSS (the server process and its children, /proc) is sampled every
``--sample-seconds`` for the table. The load runs in two phases, the warm-up (the first
``--warmup-fraction`` of the time) and the rest; after each, once every answer is in, the load pauses
``--settle-seconds`` and the idle RSS is read, so that no outfit in flight counts as growth.

Bound: the idle RSS at the end may exceed the idle RSS after the warm-up by at most
``--max-growth-mb``. Exits 1 otherwise, or when any request failed other than rejected (429/503/504,
the service's answers to overload and deadlines). Bounded: it stops after ``--minutes`` (plus the
settling and the answers in flight), or after ``--max-requests``.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import sys
import time

import httpx
import numpy as np

from benchmarks.loadgen import (
    MAX_GARMENTS,
    LocalServer,
    Result,
    Stats,
    back_off,
    check_loopback,
    fetch_catalog,
    format_table,
    make_requests,
    post_outfit,
    rss_mb,
)
from service.pipeline.body import BodyModel

# The soak's own server: a cache small enough to fill (and evict) during the warm-up.
SOAK_SERVER_ENV = {"ULNEF_CACHE_ENTRIES": "8"}
MAX_MINUTES = 240.0
SAMPLE_HEADER = ("t s", "RSS MB", "peak MB", "requests", "ok", "rejected", "errors")
PHASES = ("warm-up", "end")


async def soak(url: str, pid: int | None, args: argparse.Namespace) -> tuple[list[Result], list[tuple], dict]:
    """Returns the results, the RSS samples (SAMPLE_HEADER rows) and the idle RSS (MB) after each phase."""
    rng = np.random.default_rng(args.seed)
    catalog, body = fetch_catalog(url), BodyModel.load()
    pool = make_requests(rng, catalog, body, args.pool, list(range(1, MAX_GARMENTS + 1)))
    results: list[Result] = []
    samples: list[tuple] = []
    idle: dict[str, float] = {}
    t0 = time.perf_counter()

    def sample() -> tuple:
        rss, peak = rss_mb(pid) if pid else (float("nan"), float("nan"))
        ok = sum(r.status == 200 for r in results)
        rejected = sum(r.rejected for r in results)
        return (time.perf_counter() - t0, rss, peak, len(results), ok, rejected, len(results) - ok - rejected)

    def next_request() -> dict:
        if rng.random() < 0.5:
            return pool[int(rng.integers(0, len(pool)))]
        return make_requests(rng, catalog, body, 1, [int(rng.integers(1, MAX_GARMENTS + 1))])[0]

    async def client_loop(client: httpx.AsyncClient, until_s: float) -> None:
        while time.perf_counter() - t0 < until_s and len(results) < args.max_requests:
            results.append(await post_outfit(client, url, next_request(), glb=False))
            await back_off(results[-1])

    async def sampler() -> None:
        while True:
            samples.append(sample())
            print(format_table(SAMPLE_HEADER, [samples[-1]]).splitlines()[-1], flush=True)
            await asyncio.sleep(args.sample_seconds)

    limits = httpx.Limits(max_connections=args.concurrency)
    async with httpx.AsyncClient(timeout=args.timeout, limits=limits) as client:
        sampling = asyncio.create_task(sampler())
        total_s = args.minutes * 60
        for phase, until_s in zip(PHASES, (args.warmup_fraction * total_s, total_s), strict=True):
            await asyncio.gather(*(client_loop(client, until_s) for _ in range(args.concurrency)))
            # Every answer is in; an outfit that ran past its deadline may still be finishing.
            await asyncio.sleep(args.settle_seconds)
            idle[phase] = sample()[1]
            print(f"idle RSS after the {phase}: {idle[phase]:.0f} MB", flush=True)
        sampling.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await sampling
    samples.append(sample())
    return results, samples, idle


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--url", help="target a running server (loopback only); give --pid for its RSS")
    parser.add_argument("--pid", type=int, help="process id of the server given by --url")
    parser.add_argument("--minutes", type=float, default=10.0, help="(%(default)s)")
    parser.add_argument("--max-requests", type=int, default=100_000, help="(%(default)s)")
    parser.add_argument("--concurrency", type=int, default=2, help="(%(default)s)")
    parser.add_argument("--pool", type=int, default=8, help="distinct repeated requests (%(default)s)")
    parser.add_argument("--sample-seconds", type=float, default=10.0, help="(%(default)s)")
    parser.add_argument("--warmup-fraction", type=float, default=0.25, help="(%(default)s)")
    parser.add_argument("--settle-seconds", type=float, default=15.0,
                        help="idle time before each idle RSS reading (%(default)s)")  # fmt: skip
    parser.add_argument("--max-growth-mb", type=float, default=64.0, help="(%(default)s)")
    parser.add_argument("--timeout", type=float, default=120.0, help="per request, seconds (%(default)s)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--server-env", action="append", default=[], metavar="NAME=VALUE",
                        help="more environment for the server this command starts (repeatable)")  # fmt: skip
    args = parser.parse_args(argv)
    if not 0 < args.minutes <= MAX_MINUTES:
        parser.error(f"--minutes must be in (0, {MAX_MINUTES:g}]")
    if not 0 < args.warmup_fraction < 1:
        parser.error("--warmup-fraction must be in (0, 1)")
    if args.concurrency < 1 or args.pool < 1 or args.max_requests < 1 or args.sample_seconds <= 0:
        parser.error("--concurrency, --pool, --max-requests and --sample-seconds must be positive")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    with contextlib.ExitStack() as stack:
        if args.url:
            url, pid = check_loopback(args.url), args.pid
        else:
            env = SOAK_SERVER_ENV | dict(kv.split("=", 1) for kv in args.server_env)
            server = stack.enter_context(LocalServer(env=env))
            url, pid = server.url, server.process.pid
            print(f"server: {url}, ready in {server.startup_s:.1f} s, env {env}", flush=True)
        print(format_table(SAMPLE_HEADER, []), flush=True)
        results, samples, idle = asyncio.run(soak(url, pid, args))
    stats = Stats.of(results, samples[-1][0])
    print()
    header = ("requests", "ok", "rejected", "errors", "p50 ms", "p95 ms", "p99 ms", "req/s", "failures")
    row = [stats.sent, stats.ok, stats.rejected, stats.errors, stats.p50_ms, stats.p95_ms, stats.p99_ms,
           stats.throughput, stats.statuses or "-"]  # fmt: skip
    print(format_table(header, [row]))
    failed = stats.errors > 0
    if pid:
        growth = idle["end"] - idle["warm-up"]
        verdict = "ok" if growth <= args.max_growth_mb else "FAIL"
        print(f"\nidle RSS after the warm-up {idle['warm-up']:.0f} MB, at the end {idle['end']:.0f} MB: "
              f"growth {growth:+.0f} MB (bound {args.max_growth_mb:g} MB): {verdict}; "
              f"peak {max(s[2] for s in samples):.0f} MB")  # fmt: skip
        failed |= verdict != "ok"
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
