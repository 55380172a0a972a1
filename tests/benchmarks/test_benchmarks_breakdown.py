"""benchmarks/breakdown: its timers count onnxruntime, KD-tree and numba time, and leave the service as it
was."""

from __future__ import annotations

import numpy as np

import service.geometry.bvh_kernel
import service.geometry.closest
import service.pipeline.outfit
import service.process.onnx_session
from benchmarks.breakdown import SPENT, _instrumented
from service.geometry.closest import ClosestPoint
from service.process.paths import models_dir
from tests.meshes import grid_mesh


def test_timers_count_the_kernels_and_are_removed_after():
    import onnxruntime as ort

    before = (ort.InferenceSession.run, service.geometry.closest.cKDTree,
              service.geometry.closest.QUERY_THREADS, service.pipeline.outfit.FIT_THREADS,
              service.geometry.bvh_kernel.closest)  # fmt: skip
    for key in SPENT:
        SPENT[key] = 0.0
    vertices, faces = grid_mesh(4)
    with _instrumented(1):
        assert service.geometry.closest.QUERY_THREADS == service.pipeline.outfit.FIT_THREADS == 1
        mesh = ClosestPoint.build(vertices, faces)
        mesh.query(np.array([[0.3, 0.4, 0.1]]))  # the hierarchy's compiled search
        mesh.candidates(np.array([[0.3, 0.4, 0.1]]))  # the KD-tree, as the body map's fallback asks it
        assert SPENT["kdtree"] > 0 and SPENT["numba"] > 0 and SPENT["onnxruntime"] == 0
        session = service.process.onnx_session.open_session(models_dir() / "fields" / "body.onnx", 1)
        feeds = {i.name: np.zeros([d if isinstance(d, int) else 1 for d in i.shape], np.float32)
                 for i in session.get_inputs()}  # fmt: skip
        session.run(None, feeds)
        assert SPENT["onnxruntime"] > 0
    after = (ort.InferenceSession.run, service.geometry.closest.cKDTree,
             service.geometry.closest.QUERY_THREADS, service.pipeline.outfit.FIT_THREADS,
             service.geometry.bvh_kernel.closest)  # fmt: skip
    assert after == before


def test_the_world_clock_times_untangle_world_and_is_removed_after():
    import time

    from benchmarks.breakdown import WORLD, _world_clock

    before = service.pipeline.outfit.untangle_world
    WORLD["wall"] = WORLD["cpu"] = 0.0

    def busy(*args, **kwargs):  # a stand-in that spins one core for 50 ms
        end = time.perf_counter() + 0.05
        while time.perf_counter() < end:
            pass
        return args

    service.pipeline.outfit.untangle_world = busy
    try:
        with _world_clock():
            assert service.pipeline.outfit.untangle_world(1, 2) == (1, 2)
        assert service.pipeline.outfit.untangle_world is busy
    finally:
        service.pipeline.outfit.untangle_world = before
    assert 0.05 <= WORLD["wall"] < 0.5
    assert 0.5 < WORLD["cpu"] / WORLD["wall"] < 1.2  # one core busy
