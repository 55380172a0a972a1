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


def open_session(path: Path, threads: int):
    """An ``onnxruntime.InferenceSession`` on the CPU with ``threads`` intra-op threads."""
    import onnxruntime as ort  # lazy: only the serving path needs it

    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    options.enable_cpu_mem_arena = False
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
