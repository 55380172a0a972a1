"""Soak test: mixed outfit load for N minutes while sampling the server's RSS; fails on growth.

Run (starts ``ulnef serve`` on a free 127.0.0.1 port, with a small outfit cache so that it fills
and evicts during the warm-up)::

    python -m benchmarks.soak [--minutes 10] [--concurrency 2] [--max-growth-mb 64]
    python -m benchmarks.soak --url http://127.0.0.1:8000 --pid PID     # a running server

The load is half cold requests (a new body shape each) and half repeats from a pool of earlier
ones, 1-4 garments (see benchmarks.load). RSS (the server process and its children, /proc) is
sampled every ``--sample-seconds``. Bound: the RSS at the end may exceed the RSS at the end of the
warm-up (the first ``--warmup-fraction`` of the run) by at most ``--max-growth-mb``; the command
exits 1 otherwise, or when any request failed. Bounded: it stops after ``--minutes``, or after
``--max-requests``, whichever comes first.
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
    check_loopback,
    fetch_catalog,
    format_table,
    make_requests,
    post_outfit,
    rss_mb,
)
from service.body import BodyModel

# The soak's own server: a cache small enough to fill (and evict) during the warm-up.
SOAK_SERVER_ENV = {"ULNEF_CACHE_ENTRIES": "8"}
MAX_MINUTES = 240.0


async def soak(url: str, pid: int | None, args: argparse.Namespace) -> tuple[list[Result], list[tuple]]:
    rng = np.random.default_rng(args.seed)
    catalog, body = fetch_catalog(url), BodyModel.load()
    sizes = list(range(1, MAX_GARMENTS + 1))
    pool = make_requests(rng, catalog, body, args.pool, sizes)
    results: list[Result] = []
    samples: list[tuple] = []  # (seconds, rss MB, peak MB, requests done, errors)
    t0 = time.perf_counter()
    end = t0 + args.minutes * 60

    def next_request() -> dict:
        if rng.random() < 0.5:
            return pool[int(rng.integers(0, len(pool)))]
        return make_requests(rng, catalog, body, 1, [int(rng.integers(1, MAX_GARMENTS + 1))])[0]

    async def client_loop(client: httpx.AsyncClient) -> None:
        while time.perf_counter() < end and len(results) < args.max_requests:
            results.append(await post_outfit(client, url, next_request(), glb=False))

    async def sampler() -> None:
        while True:
            rss, peak = rss_mb(pid) if pid else (float("nan"), float("nan"))
            errors = sum(r.status != 200 for r in results)
            samples.append((time.perf_counter() - t0, rss, peak, len(results), errors))
            print(format_table(SAMPLE_HEADER, [samples[-1]]).splitlines()[-1], flush=True)
            await asyncio.sleep(args.sample_seconds)

    limits = httpx.Limits(max_connections=args.concurrency)
    async with httpx.AsyncClient(timeout=args.timeout, limits=limits) as client:
        sampling = asyncio.create_task(sampler())
        await asyncio.gather(*(client_loop(client) for _ in range(args.concurrency)))
        sampling.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await sampling
    rss, peak = rss_mb(pid) if pid else (float("nan"), float("nan"))
    samples.append((time.perf_counter() - t0, rss, peak, len(results), sum(r.status != 200 for r in results)))
    return results, samples


SAMPLE_HEADER = ("t s", "RSS MB", "peak MB", "requests", "errors")


def growth_mb(samples: list[tuple], warmup_fraction: float) -> tuple[float, float]:
    """(RSS at the end of the warm-up, growth after it) in MB."""
    total = samples[-1][0]
    after = [s for s in samples if s[0] >= warmup_fraction * total]
    baseline = after[0][1]
    return baseline, samples[-1][1] - baseline


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
    parser.add_argument("--max-growth-mb", type=float, default=64.0, help="(%(default)s)")
    parser.add_argument("--timeout", type=float, default=120.0, help="per request, seconds (%(default)s)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--server-env", action="append", default=[], metavar="NAME=VALUE",
                        help="more environment for the server this command starts (repeatable)")  # fmt: skip
    args = parser.parse_args(argv)
    if not 0 < args.minutes <= MAX_MINUTES:
        parser.error(f"--minutes must be in (0, {MAX_MINUTES:g}]")
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
        results, samples = asyncio.run(soak(url, pid, args))
    stats = Stats.of(results, samples[-1][0])
    print()
    print(format_table(("requests", "ok", "errors", "p50 ms", "p95 ms", "p99 ms", "req/s", "failures"),
                       [[stats.sent, stats.ok, stats.errors, stats.p50_ms, stats.p95_ms, stats.p99_ms,
                         stats.throughput, stats.statuses or "-"]]))  # fmt: skip
    failed = stats.errors > 0
    if pid:
        baseline, growth = growth_mb(samples, args.warmup_fraction)
        verdict = "ok" if growth <= args.max_growth_mb else "FAIL"
        peak = max(s[2] for s in samples)
        print(f"\nRSS after warm-up {baseline:.0f} MB, at the end {samples[-1][1]:.0f} MB, "
              f"growth {growth:+.0f} MB (bound {args.max_growth_mb:g} MB): {verdict}; peak {peak:.0f} MB")
        failed |= verdict != "ok"
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
