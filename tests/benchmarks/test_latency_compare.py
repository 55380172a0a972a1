"""``benchmarks.latency --compare``: a worker process answers outfits with their stage timings, for
the ``service`` of the tree it is pointed at."""

from __future__ import annotations

from benchmarks.latency import REPO, STAGES, _row, _Worker


def test_a_worker_times_outfits_of_its_tree():
    worker = _Worker(REPO, threads=1)
    try:
        seconds = [worker(("shorts",), beta) for beta in ([0.5, 0.4, 0.5], [0.2, 0.6, 0.8])]
    finally:
        worker.close()
    assert worker.proc.returncode == 0
    for s in seconds:
        assert s["total"] > 0 and {"body", "explicit", "fit", "world"} <= set(s)
    row = _row(("shorts",), seconds)
    assert row.startswith("| body + shorts | ") and row.count("|") == len(STAGES) + 4
