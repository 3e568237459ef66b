"""Work spread over threads within one process (stages 0-2, beyond the thesis).

Stage 3 fans out over processes (:func:`engine.pipeline.all_candidates`, worker chunks);
stages 0-2 run in one task, where a process pool would have to ship the video to each child.
Their hot loops are per video frame and spend their time in code that releases the GIL (the
numba raster kernels are compiled ``nogil``; OpenCV's GrabCut, numpy's large operations), so
threads share the frames at no copying cost. Each item's result is computed alone, so the
results do not depend on the number of threads.
"""

from __future__ import annotations

import os
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from itertools import islice
from typing import TypeVar

T = TypeVar("T")
R = TypeVar("R")


def thread_count(threads: int) -> int:
    """``threads``, or with 0 the cores this process may run on."""
    if threads < 0:
        raise ValueError(f"threads must be >= 0, got {threads}")
    return threads or len(os.sched_getaffinity(0))


def map_in_threads(fn: Callable[[T], R], items: Iterable[T], threads: int) -> Iterator[R]:
    """``fn`` over ``items`` on ``threads`` threads (0: every core), results in order.

    Results are yielded as they come, so a caller can report progress and stop between
    items: when the consumer raises (a cancelled analysis) or stops iterating, items not yet
    started are dropped and the running ones finish before this returns. At most
    ``2 threads`` items are in flight, so results wait for their consumer a few at a time
    (stage 0's are three images per frame), not a whole video's worth.
    """
    n = thread_count(threads)
    if n == 1:
        yield from map(fn, items)
        return
    todo = iter(items)
    pool = ThreadPoolExecutor(max_workers=n, thread_name_prefix="coach-stage")
    try:
        flight = deque(pool.submit(fn, item) for item in islice(todo, 2 * n))
        while flight:
            result = flight.popleft().result()
            flight.extend(pool.submit(fn, item) for item in islice(todo, 1))
            yield result
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
