"""engine.threads: stages 0-2 share their frames over threads, in order, and stop cleanly."""

from __future__ import annotations

import os
import threading
import time

import pytest

from engine.threads import map_in_threads, thread_count


def test_results_come_in_order_whichever_thread_finishes_first():
    def slow_first(i: int) -> tuple[int, str]:
        time.sleep(0.05 if i == 0 else 0.0)  # item 0 finishes last
        return i * i, threading.current_thread().name

    out = list(map_in_threads(slow_first, range(6), threads=2))
    assert [v for v, _ in out] == [0, 1, 4, 9, 16, 25]
    assert {name.startswith("coach-stage") for _, name in out} == {True}
    # one thread: the caller's own, no pool
    assert {n for _, n in map_in_threads(slow_first, range(3), threads=1)} == {
        threading.current_thread().name
    }


def test_a_consumer_that_stops_drops_the_items_not_started():
    started: list[int] = []
    gate = threading.Event()

    def work(i: int) -> int:
        started.append(i)
        gate.wait(1.0)  # the first two hold both threads until the consumer has stopped
        return i

    items = map_in_threads(work, range(50), threads=2)
    with pytest.raises(RuntimeError, match="cancelled"):
        for _ in items:
            gate.set()
            raise RuntimeError("cancelled")  # what a cancelled analysis' progress call does
    items.close()
    assert len(started) < 50, len(started)  # most were dropped, not run
    n = len(started)
    time.sleep(0.1)
    assert len(started) == n  # and none starts afterwards


def test_thread_count():
    assert thread_count(3) == 3
    assert thread_count(0) == len(os.sched_getaffinity(0))
    with pytest.raises(ValueError, match="threads"):
        thread_count(-1)
