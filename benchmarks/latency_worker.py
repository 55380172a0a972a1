"""One side of ``benchmarks.latency --compare``: outfits on request, timed, for the ``service`` on
``PYTHONPATH`` (this tree's or a git worktree's, with its own models).

Reads JSON lines ``{"garments": [...], "body": [gender, height_cm, weight_kg]}`` on stdin and answers
each with the request's ``report["seconds"]`` as one JSON line, the body's build included in "body"
and "total" (``outfit_seconds``); first it prints ``{"ready": true}``. Run as a file
(``python benchmarks/latency_worker.py THREADS``), so that the imported ``service`` is the one the
caller put on ``PYTHONPATH``, whatever this file's tree.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np


def outfit_seconds(models, garments: list[str], body: list[float]) -> dict:
    """``report["seconds"]`` of one outfit on the body of (gender, height_cm, weight_kg), made as the
    tree's service makes it: since issue 55 a shopper's body (``models.bodies``, new to its cache here:
    every benchmark body is), before it the box body of that height and weight."""
    from service.pipeline.outfit import make_outfit

    start = time.perf_counter()
    built = None
    if hasattr(models, "bodies"):
        from service.pipeline.body_build import BodyRequest

        built = models.bodies.build(BodyRequest(*body))
        try:  # the service's body as dressed (issue 55), in a tree that has it
            from service.pipeline.dressed_body import dressed_vertices

            vertices = dressed_vertices(models.body, built)
        except ImportError:
            vertices = models.body.shape_vertices(built.shape)
        beta, extra = built.garment_beta, {"body_vertices": vertices}
    else:
        from service.pipeline.body import shape_from_measurements

        beta, extra = shape_from_measurements(models.body, *body), {}
    built_s = time.perf_counter() - start
    seconds = make_outfit(models, garments, np.asarray(beta), measure=False, **extra).report["seconds"]
    if built is not None:  # the service reports the body as measured, measured meanwhile in a tree
        start = time.perf_counter()
        built.report()
        built_s += time.perf_counter() - start
    return seconds | {"body": seconds["body"] + built_s, "total": seconds["total"] + built_s}


def main() -> None:
    from service.pipeline.outfit import OutfitModels

    models = OutfitModels.load(threads=int(sys.argv[1]) if len(sys.argv) > 1 else 2)
    if hasattr(models, "warm"):  # as the service starts (trees before the junctions have none)
        models.warm()
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        request = json.loads(line)
        print(json.dumps(outfit_seconds(models, request["garments"], request["body"])), flush=True)


if __name__ == "__main__":
    main()
