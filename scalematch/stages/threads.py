"""Threads for independent pieces of numpy and OpenCV work (issue 12).

numpy's matrix products and reductions and OpenCV's functions release the GIL, so independent
pieces of work (chunks of a descriptor match, the scales of the full pass) run in parallel on
threads. As many threads as OpenCV uses (``cv2.getNumThreads()``: the cores, or 1 where the
batch command's workers set it, one process per core). A map called from inside another runs
serially, so pools never wait on themselves. Each piece is computed alone: the answer does not
depend on the threads.
"""

from __future__ import annotations

import threading
from typing import Callable, Iterable, List, TypeVar

import cv2

T = TypeVar("T")
R = TypeVar("R")

_pool = None
_local = threading.local()


def thread_map(fn: Callable[[T], R], items: Iterable[T]) -> List[R]:
    """``[fn(x) for x in items]``, in that order, computed on threads when there are some.

    >>> thread_map(lambda x: x * x, range(5))
    [0, 1, 4, 9, 16]
    """
    global _pool
    items = list(items)
    threads = max(1, cv2.getNumThreads())
    if threads == 1 or len(items) < 2 or getattr(_local, "inside", False):
        return [fn(x) for x in items]
    if _pool is None or _pool._max_workers != threads:
        from concurrent.futures import ThreadPoolExecutor

        _pool = ThreadPoolExecutor(threads, thread_name_prefix="scalematch")

    def run(x: T) -> R:
        _local.inside = True
        try:
            return fn(x)
        finally:
            _local.inside = False
    return list(_pool.map(run, items))
