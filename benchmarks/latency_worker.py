"""One side of ``benchmarks.latency --compare``: outfits on request, timed, for the ``service`` on
``PYTHONPATH`` (this tree's or a git worktree's, with its own models).

Reads JSON lines ``{"garments": [...], "beta": [3 floats]}`` on stdin and answers each with the
request's ``report["seconds"]`` as one JSON line; first it prints ``{"ready": true}``. Run as a file
(``python benchmarks/latency_worker.py THREADS``), so that the imported ``service`` is the one the
caller put on ``PYTHONPATH``, whatever this file's tree.
"""

from __future__ import annotations

import json
import sys

import numpy as np


def main() -> None:
    from service.pipeline.outfit import OutfitModels, make_outfit

    models = OutfitModels.load(threads=int(sys.argv[1]) if len(sys.argv) > 1 else 2)
    if hasattr(models, "warm"):  # as the service starts (trees before the junctions have none)
        models.warm()
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        request = json.loads(line)
        report = make_outfit(models, request["garments"], np.array(request["beta"]), measure=False).report
        print(json.dumps(report["seconds"]), flush=True)


if __name__ == "__main__":
    main()
