"""benchmarks/breakdown: its timers count onnxruntime, KD-tree and numba time, and leave the service as it
was."""

from __future__ import annotations

import numpy as np
import pytest

import service.geometry.bvh_kernel
import service.geometry.closest
import service.pipeline.outfit
import service.process.onnx_session
from benchmarks.breakdown import SPENT, _instrumented
from service.geometry.closest import ClosestPoint
from service.process.paths import models_dir
from tests.meshes import grid_mesh


class FakeClock:
    """``perf_counter`` and ``process_time`` that move only when a test moves them: no timing here
    depends on how busy the machine is."""

    def __init__(self):
        self.wall = self.cpu = 0.0

    def perf_counter(self) -> float:
        return self.wall

    def process_time(self) -> float:
        return self.cpu


def test_timers_count_the_kernels_and_are_removed_after(monkeypatch):
    import onnxruntime as ort

    import benchmarks.breakdown

    ticking = FakeClock()

    def tick() -> float:  # each reading a millisecond later: a timed call counts, however fast
        ticking.wall += 1e-3
        return ticking.wall

    ticking.perf_counter = tick
    monkeypatch.setattr(benchmarks.breakdown, "time", ticking)

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


def test_the_world_clock_times_the_collision_passes_and_is_removed_after(monkeypatch):
    import benchmarks.breakdown
    from benchmarks.breakdown import WORLD, _world_clock

    clock = FakeClock()
    monkeypatch.setattr(benchmarks.breakdown, "time", clock)
    calls = []

    def stand_in(*args, **kwargs):  # 50 ms of wall time, 30 ms of it on a core
        calls.append(args)
        clock.wall += 0.05
        clock.cpu += 0.03
        if args == ("fails",):
            raise ValueError("a failing call is timed too")
        return args

    monkeypatch.setattr(service.pipeline.outfit, "resolve", stand_in)
    WORLD["wall"] = WORLD["cpu"] = 0.0
    with _world_clock():
        assert service.pipeline.outfit.resolve is not stand_in  # wrapped
        assert service.pipeline.outfit.resolve(1, 2) == (1, 2)
        clock.wall += 1.0  # time outside resolve is not counted
        clock.cpu += 1.0
        with pytest.raises(ValueError):
            service.pipeline.outfit.resolve("fails")
    assert service.pipeline.outfit.resolve is stand_in
    assert calls == [(1, 2), ("fails",)]
    assert WORLD == {"wall": pytest.approx(0.1), "cpu": pytest.approx(0.06)}
