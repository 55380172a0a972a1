"""The bounded worker pool: capacity, refusal, deadlines, and slots held until a job really ends."""

from __future__ import annotations

import threading
import time

import pytest

from service.server.worker import BoundedWorker, DeadlineExceeded, Overloaded
from tests.service_tools import wait_until


def test_refuses_beyond_capacity_and_frees_slots():
    worker = BoundedWorker(workers=1, queue_size=1, initial_job_s=0.01)
    gate = threading.Event()
    far = time.monotonic() + 60
    running = worker.submit(gate.wait, far)
    queued = worker.submit(lambda: "queued", far)
    with pytest.raises(Overloaded, match="2 outfits in progress, at capacity") as refused:
        worker.submit(lambda: "refused", far)
    assert refused.value.retry_after >= 1
    assert worker.pending == 2
    gate.set()
    assert running.result(5) is True and queued.result(5) == "queued"
    assert worker.pending == 0 and worker.running == 0
    assert worker.submit(lambda: "again", far).result(5) == "again"
    worker.shutdown()


def test_a_job_whose_deadline_passed_in_the_queue_is_not_run():
    worker = BoundedWorker(workers=1, queue_size=4, initial_job_s=0.01)
    gate = threading.Event()
    ran = []
    worker.submit(gate.wait, time.monotonic() + 60)
    late_deadline = time.monotonic() + 0.05
    late = worker.submit(lambda: ran.append(1), late_deadline)
    wait_until(lambda: time.monotonic() > late_deadline, 5, "the queued job's deadline never passed")
    gate.set()
    with pytest.raises(DeadlineExceeded):
        late.result(5)
    assert ran == [] and worker.pending == 0
    worker.shutdown()


def test_refuses_when_the_estimated_wait_exceeds_the_deadline():
    worker = BoundedWorker(workers=1, queue_size=10, initial_job_s=5.0)
    gate = threading.Event()
    worker.submit(gate.wait, time.monotonic() + 60)
    with pytest.raises(Overloaded, match="estimated wait 10.0 s exceeds"):
        worker.submit(lambda: None, time.monotonic() + 1.0)
    gate.set()
    worker.shutdown()


def test_retry_after_follows_measured_job_time():
    worker = BoundedWorker(workers=2, queue_size=2, initial_job_s=1.0)
    for _ in range(30):
        worker.submit(lambda: time.sleep(0.001), time.monotonic() + 60).result(5)
    assert worker.retry_after() == 1  # jobs of ~1 ms: retry after the 1 s minimum
    worker._job_s = 30.0
    worker._pending = 4
    assert worker.retry_after() == 60  # capped
    worker.shutdown()


def test_a_reserved_place_counts_until_its_job_ends_or_it_is_released():
    worker = BoundedWorker(workers=1, queue_size=0, initial_job_s=0.01)
    far = time.monotonic() + 60
    worker.reserve(far)
    with pytest.raises(Overloaded, match="^1 outfits in progress, at capacity$"):
        worker.reserve(far)
    worker.release()
    worker.reserve(far)
    assert worker.pending == 1
    assert worker.submit(lambda: "reserved", far, reserved=True).result(5) == "reserved"
    assert worker.pending == 0
    worker.shutdown()
