"""HTTP load test of POST /v1/outfits: latency percentiles, throughput and errors.

Run (starts ``ulnef serve`` on a free 127.0.0.1 port and stops it at the end)::

    python -m benchmarks.load [--requests 20] [--concurrency 1,4] [--max-seconds 300]
    python -m benchmarks.load --url http://127.0.0.1:8000     # a server already running on loopback

Outfits are 1-4 garments from GET /v1/garments (tops in stacking order, at most one bottom at a
random place among them) on random body shapes inside the supported range (``service.pipeline.body``).
Scenarios, each at every concurrency:

- cold: every request a new body shape, so no cache can answer it;
- warm: ``--warm-pool`` requests sent once untimed, then repeated at random (the outfit cache).

"rejected" counts 429/503/504 answers (overload or deadline, with Retry-After; the client waits that
long, at most 5 s, before its next request); "errors" every other failure.

Prints one table over scenarios and one of cold latency by garment count at the lowest concurrency
(the issue's targets are cold, one request at a time, body + 2 and body + 3 garments). Bounded:
``--requests`` per scenario, and no request starts after ``--max-seconds`` of a scenario. Seeded:
the same requests every run.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json

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
    rss_mb,
    run_requests,
)
from service.pipeline.body import BodyModel

SCENARIO_HEADER = ("scenario", "concurrency", "sent", "ok", "rejected", "errors", "p50 ms", "p95 ms",
                   "p99 ms", "req/s", "cache hits", "failures")  # fmt: skip


def run_scenarios(url: str, args: argparse.Namespace) -> tuple[list[list[object]], list[Result]]:
    """The scenario table's rows, and the cold results at the lowest concurrency."""
    rng = np.random.default_rng(args.seed)
    catalog = fetch_catalog(url)
    body = BodyModel.load()
    sizes = list(range(1, MAX_GARMENTS + 1))
    rows, cold_one_at_a_time = [], []
    for concurrency in args.concurrency:
        for scenario in ("cold", "warm"):
            if scenario == "cold":
                requests = make_requests(rng, catalog, body, args.requests, sizes)
            else:
                pool = make_requests(rng, catalog, body, args.warm_pool, sizes)
                asyncio.run(run_requests(url, pool, concurrency, args.max_seconds, args.timeout, args.glb))
                requests = [pool[i] for i in rng.integers(0, len(pool), args.requests)]
            results, wall = asyncio.run(
                run_requests(url, requests, concurrency, args.max_seconds, args.timeout, args.glb)
            )
            stats = Stats.of(results, wall)
            hits = sum(r.cached is True for r in results)
            rows.append([scenario, concurrency, stats.sent, stats.ok, stats.rejected, stats.errors,
                         stats.p50_ms, stats.p95_ms, stats.p99_ms, stats.throughput, hits,
                         stats.statuses or "-"])  # fmt: skip
            print(format_table(SCENARIO_HEADER, rows[-1:]).splitlines()[-1], flush=True)
            if scenario == "cold" and concurrency == min(args.concurrency):
                cold_one_at_a_time = results
    return rows, cold_one_at_a_time


def by_garment_count(results: list[Result]) -> list[list[object]]:
    rows = []
    for n in sorted({r.n_garments for r in results}):
        stats = Stats.of([r for r in results if r.n_garments == n], wall_s=0.0)
        rows.append([f"body + {n}", stats.sent, stats.ok, stats.p50_ms, stats.p95_ms])
    return rows


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--url", help="target a running server (loopback only) instead of starting one")
    parser.add_argument("--requests", type=int, default=20, help="timed requests per scenario (%(default)s)")
    parser.add_argument("--concurrency", default="1,4", help="comma-separated (%(default)s)")
    parser.add_argument("--warm-pool", type=int, default=4, help="distinct requests repeated when warm")
    parser.add_argument("--max-seconds", type=float, default=300.0, help="per scenario (%(default)s)")
    parser.add_argument("--timeout", type=float, default=120.0, help="per request, seconds (%(default)s)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--glb", action="store_true", help="ask for the GLB (Accept: model/gltf-binary)")
    parser.add_argument("--server-env", action="append", default=[], metavar="NAME=VALUE",
                        help="environment of the server this command starts (repeatable)")  # fmt: skip
    parser.add_argument("--json", metavar="PATH", help="also write the tables as JSON")
    args = parser.parse_args(argv)
    args.concurrency = [int(c) for c in args.concurrency.split(",")]
    if args.requests < 1 or args.warm_pool < 1 or min(args.concurrency) < 1:
        parser.error("--requests, --warm-pool and every concurrency must be >= 1")
    return args


def main(argv=None) -> None:
    args = parse_args(argv)
    with contextlib.ExitStack() as stack:
        server = None
        if args.url:
            url = check_loopback(args.url)
        else:
            server = stack.enter_context(LocalServer(env=dict(kv.split("=", 1) for kv in args.server_env)))
            url = server.url
            print(f"server: {url}, ready in {server.startup_s:.1f} s", flush=True)
        print(format_table(SCENARIO_HEADER, []), flush=True)
        rows, cold = run_scenarios(url, args)
        print(f"\nCold, concurrency {min(args.concurrency)}, by garment count:")
        counts = by_garment_count(cold)
        print(format_table(("outfit", "sent", "ok", "p50 ms", "p95 ms"), counts))
        if server is not None:
            rss, peak = rss_mb(server.process.pid)
            print(f"\nserver RSS at the end: {rss:.0f} MB (peak {peak:.0f} MB)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"scenarios": [dict(zip(SCENARIO_HEADER, r, strict=True)) for r in rows],
                       "cold_by_garments": counts}, f, indent=2)  # fmt: skip


if __name__ == "__main__":
    main()
