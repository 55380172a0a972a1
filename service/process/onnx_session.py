"""The one way the service opens an onnxruntime session (fields, explicit models, untangler).

- No CPU memory arena: onnxruntime's arena keeps each session's largest batch for ever; 15 sessions
  held ~600 MB after one outfit of every garment (``benchmarks/memory.py``). Without it, freed buffers
  go back to malloc, which every session shares (``service.process.tuning`` keeps them in the heap).
- No spinning: each session owns a pool of ``threads - 1`` workers that by default spin for a while
  after every run, waiting for more work. The service holds ~20 sessions and calls them in turn, so
  the spinning workers of the last one took a core from the next: a field at 30,000 points took 33 ms
  with the whole model set loaded and 15 ms alone.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from service.process.threads import pool

MIN_BLOCK = 1024
"""Points below which a call is not split over threads (handing a batch to a thread costs ~0.1 ms)."""


def open_session(path: Path, threads: int):
    """An ``onnxruntime.InferenceSession`` on the CPU with ``threads`` intra-op threads."""
    import onnxruntime as ort  # lazy: only the serving path needs it

    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    options.enable_cpu_mem_arena = False
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def run_blocks(session, names: list[str], inputs: dict, points: set[str], batch: int, threads: int) -> list:
    """``session.run(names, inputs)`` with the ``points`` inputs (the others broadcast, e.g. a shape
    beta (1, 3)) cut along their first axis into batches (``blocks``), and the outputs joined again.
    The batches are dealt out in ``threads`` runs of consecutive ones, each run in turn on a thread of
    its own: the sessions have one intra-op thread each, since onnxruntime's own threads, splitting
    every matrix product of a small network, did less (a field at 30,000 points: 17.2 ms for values
    and 35.1 ms with grad f on two intra-op threads, 12.3 and 28.6 ms in batches on two threads). A
    point's answer does not depend on its batch (tested), so the result is the one call's, bit for
    bit."""
    n = len(next(v for k, v in inputs.items() if k in points))
    parts = blocks(n, batch, threads)

    def run(group: list[slice]):
        return [session.run(names, {k: (v[p] if k in points else v) for k, v in inputs.items()})
                for p in group]

    if len(parts) == 1 or threads <= 1:
        out = run(parts)
    else:
        # One hand-over per thread, not per batch: a hand-over costs ~0.1 ms, a batch ~0.5-1 ms.
        runs = [parts[i * len(parts) // threads : (i + 1) * len(parts) // threads] for i in range(threads)]
        out = [o for done in pool("onnx", threads).map(run, runs) for o in done]
    return [np.concatenate([o[k] for o in out]) if len(out) > 1 else out[0][k] for k in range(len(names))]


def blocks(n: int, batch: int, threads: int) -> list[slice]:
    """Slices of ``n`` points for one evaluation: at most ``batch`` points each (bounded activations),
    and from ``threads * MIN_BLOCK`` points as many as a multiple of ``threads`` (none waits alone
    at the end)."""
    count = max(1, -(-n // batch))
    if threads > 1 and n >= threads * MIN_BLOCK:
        count = -(-count // threads) * threads
    edges = np.linspace(0, n, count + 1).round().astype(np.int64)
    return [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]
