"""The named thread pools: one per name and size in a process, a new one in a forked child."""

from __future__ import annotations

import service.process.threads as threads


def test_one_pool_per_name_and_a_fresh_one_after_a_fork(monkeypatch):
    a = threads.pool("test-a", 2)
    assert threads.pool("test-a", 2) is a
    assert threads.pool("test-b", 2) is not a  # a stage waiting on another must not share its threads
    assert list(a.map(lambda x: x * x, range(4))) == [0, 1, 4, 9]
    monkeypatch.setattr(threads.os, "getpid", lambda: -1)  # as in a forked child
    assert threads.pool("test-a", 2) is not a
