"""A bounded pool for the CPU-bound pipeline, so the event loop never computes an outfit.

At most ``workers`` jobs run and ``queue_size`` wait; a job beyond that is refused at once
(``Overloaded``) rather than queued without bound, and so is one whose estimated wait already
exceeds its deadline. A queued job whose deadline passed before a worker picked it up is dropped
unrun (``DeadlineExceeded``). A running job cannot be interrupted (numpy and onnxruntime calls
are not cancellable), so its slot is held until it finishes: memory stays bounded by the slots.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TypeVar

T = TypeVar("T")
# Weight of the newest job in the running mean of job seconds (used for Retry-After).
EMA_WEIGHT = 0.2


class Overloaded(Exception):
    """No room for the job; retry after ``retry_after`` seconds."""

    def __init__(self, message: str, retry_after: int):
        super().__init__(message)
        self.retry_after = retry_after


class DeadlineExceeded(Exception):
    """The job's deadline passed before it could start or finish."""


class BoundedWorker:
    """``workers`` threads, ``queue_size`` waiting places, deadlines in ``time.monotonic()`` seconds."""

    def __init__(self, workers: int, queue_size: int, initial_job_s: float = 1.0):
        self.workers = workers
        self.capacity = workers + queue_size
        self._pool = ThreadPoolExecutor(workers, thread_name_prefix="outfit")
        self._lock = threading.Lock()
        self._pending = 0  # running + queued
        self._running = 0
        self._job_s = initial_job_s

    @property
    def pending(self) -> int:
        return self._pending

    @property
    def running(self) -> int:
        return self._running

    def retry_after(self) -> int:
        """Seconds until a slot is likely free: the queue ahead divided among the workers."""
        return max(1, min(60, math.ceil(self._job_s * max(self._pending, 1) / self.workers)))

    def check_room(self) -> None:
        """Raise ``Overloaded`` when every place is taken."""
        if self._pending >= self.capacity:
            raise Overloaded(f"{self._pending} outfits in progress, at capacity", self.retry_after())

    def reserve(self, deadline: float) -> None:
        """Take a place for a job ``submit(..., reserved=True)`` will bring, or raise ``Overloaded`` at
        once: a full house (or a wait past ``deadline``) is refused before the request is validated,
        so a refusal never waits behind other requests' work. ``release`` a place left unused."""
        with self._lock:
            self.check_room()
            wait = self._job_s * (self._pending // self.workers + 1)
            if time.monotonic() + wait > deadline and self._pending >= self.workers:
                raise Overloaded(f"estimated wait {wait:.1f} s exceeds the request's time budget",
                                 self.retry_after())  # fmt: skip
            self._pending += 1

    def release(self) -> None:
        """Give back a place ``reserve`` took for a job that will not come (refused, or shared)."""
        with self._lock:
            self._pending -= 1

    def submit(self, fn: Callable[[], T], deadline: float, reserved: bool = False) -> Future[T]:
        """Queue ``fn``; in the place ``reserve`` took when ``reserved``, else in one taken now."""
        if not reserved:
            self.reserve(deadline)
        try:
            return self._pool.submit(self._run, fn, deadline)
        except RuntimeError:  # pool shut down
            if not reserved:  # a reserved place is its reserver's to release
                self.release()
            raise

    def _run(self, fn: Callable[[], T], deadline: float) -> T:
        try:
            if time.monotonic() > deadline:
                raise DeadlineExceeded("deadline passed while queued")
            with self._lock:
                self._running += 1
            t0 = time.perf_counter()
            try:
                return fn()
            finally:
                seconds = time.perf_counter() - t0
                with self._lock:
                    self._running -= 1
                    self._job_s += EMA_WEIGHT * (seconds - self._job_s)
        finally:
            with self._lock:
                self._pending -= 1

    def shutdown(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
