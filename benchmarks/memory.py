"""Server memory with the whole catalog loaded: RSS of ``ulnef serve`` at each step; target <= 600 MB.

Run (starts the server on a free 127.0.0.1 port)::

    python -m benchmarks.memory [--target-mb 600]
    python -m benchmarks.memory --url http://127.0.0.1:8000 --pid PID     # a running server

Steps: ready (models loaded, self-test done), then outfits that between them use every catalog
garment (all tops stacked, then each bottom on its own), so every garment's explicit model and
field has run at least once. RSS is the process and its children (/proc), in MB (10^6 bytes);
peak is the high-water mark. Exits 1 when the RSS after the outfits exceeds ``--target-mb``.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import sys

import numpy as np

from benchmarks.loadgen import (
    MAX_GARMENTS,
    LocalServer,
    check_loopback,
    fetch_catalog,
    format_table,
    outfit_request,
    random_body,
    rss_mb,
    run_requests,
)
from service.pipeline.body import BodyModel


def covering_outfits(tops: tuple[str, ...], bottoms: tuple[str, ...]) -> list[list[str]]:
    """Outfits of at most MAX_GARMENTS that together use every garment once."""
    outfits = [list(tops[i : i + MAX_GARMENTS]) for i in range(0, len(tops), MAX_GARMENTS)]
    return outfits + [[b] for b in bottoms]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--url", help="target a running server (loopback only) instead of starting one")
    parser.add_argument("--pid", type=int, help="process id of the server given by --url")
    parser.add_argument("--target-mb", type=float, default=600.0, help="(%(default)s)")
    parser.add_argument("--timeout", type=float, default=300.0, help="per request, seconds (%(default)s)")
    args = parser.parse_args(argv)
    if args.url and not args.pid:
        parser.error("--url needs --pid (the server's process id) to read its memory")
    header = ("step", "status", "RSS MB", "peak MB")
    rows = []
    with contextlib.ExitStack() as stack:
        if args.url:
            url, pid = check_loopback(args.url), args.pid
        else:
            # Memory, not latency: a request budget as long as the client waits.
            server = stack.enter_context(LocalServer(env={"ULNEF_REQUEST_TIMEOUT_S": str(args.timeout)}))
            url, pid = server.url, server.process.pid
        rows.append(["ready (models loaded)", "-", *rss_mb(pid)])
        catalog = fetch_catalog(url)
        body, rng = BodyModel.load(), np.random.default_rng(0)
        for outfit in covering_outfits(catalog.tops, catalog.bottoms):
            request = outfit_request(outfit, random_body(rng, body))
            (result,), _ = asyncio.run(run_requests(url, [request], 1, args.timeout, args.timeout, glb=False))
            rows.append([f"after {','.join(outfit)}", result.status, *rss_mb(pid)])
            print(format_table(header, rows[-1:]).splitlines()[-1], flush=True)
    print()
    print(format_table(header, rows))
    final = rows[-1][2]
    ok = final <= args.target_mb and all(r[1] in ("-", 200) for r in rows)
    print(f"\nRSS with the whole catalog loaded: {final:.0f} MB (target <= {args.target_mb:g} MB): "
          f"{'ok' if ok else 'FAIL'}")  # fmt: skip
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
