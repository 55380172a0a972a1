"""service.process.tuning: the process settings the pipeline's speed measurements rely on take effect."""

from __future__ import annotations

import json
import subprocess
import sys

PROBE = """
import json, numpy
from threadpoolctl import threadpool_info
from service.process.tuning import tune_process
applied = tune_process()
blas = [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]
print(json.dumps({"applied": applied, "blas": blas, "again": tune_process()}))
"""


def test_tune_process_limits_blas_and_sets_malloc():
    run = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, check=True, text=True)
    out = json.loads(run.stdout)
    assert out["applied"] == {"malloc": True, "blas": True}  # glibc Linux, threadpoolctl installed
    assert out["blas"] and all(n == 1 for n in out["blas"])
    assert out["again"] == out["applied"]  # idempotent
