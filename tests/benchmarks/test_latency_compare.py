"""``benchmarks.latency --compare``: a worker process answers outfits with their stage timings, for
the ``service`` of the tree it is pointed at."""

from __future__ import annotations

import numpy as np

from benchmarks.latency import REPO, STAGES, _row, _Worker, human_units, new_body


def test_a_worker_times_outfits_of_its_tree():
    """Asked in human units; the body's build is in "body" and "total" (a woman of BMI 45 is served)."""
    worker = _Worker(REPO, threads=1)
    try:
        seconds = [worker(("shorts",), body) for body in ([0.5, 170.0, 65.0], [1.0, 160.0, 115.0])]
    finally:
        worker.close()
    assert worker.proc.returncode == 0
    for s in seconds:
        assert s["total"] > 0 and {"body", "explicit", "fit", "world"} <= set(s)
        assert s["body"] > 0
    row = _row(("shorts",), seconds)
    assert row.startswith("| body + shorts | ") and row.count("|") == len(STAGES) + 4


def test_requests_are_the_box_bodies_in_human_units_and_new_per_row():
    from service.pipeline.body import BodyModel, shape_from_measurements

    betas = np.array([[0.0, 0.3, 0.2], [1.0, 0.6, 0.9]])
    bodies = human_units(betas)
    model = BodyModel.load()
    for beta, (g, h, w) in zip(betas, bodies, strict=True):
        np.testing.assert_allclose(shape_from_measurements(model, g, h, w), beta, atol=1e-6)
    assert (
        new_body(bodies[0], 2) != new_body(bodies[0], 1)
        and abs(new_body(bodies[0], 3)[1] - bodies[0][1]) < 0.01
    )
