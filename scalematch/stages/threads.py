"""Threads for independent pieces of numpy and OpenCV work (docs/design/SPEED.md, "Threads").

numpy's matrix products and reductions and OpenCV's functions release the GIL, so independent
pieces of work (chunks of a descriptor match, the scales of the full pass) run in parallel on
threads. As many threads as OpenCV uses (``cv2.getNumThreads()``: the cores, or 1 where the
batch command's workers set it, one process per core), the calling thread being one of them. A
map called from inside another runs serially, so the threads never wait on themselves. Each
piece is computed alone: the answer does not depend on the threads.

The pool is a queue and daemon threads: ``concurrent.futures`` would import ``logging`` and
more, 7-10 ms of every command's start-up (``python -X importtime``).
"""

from __future__ import annotations

import threading
from queue import Empty, SimpleQueue
from typing import Callable, Iterable, List, TypeVar

import cv2

T = TypeVar("T")
R = TypeVar("R")

_jobs: SimpleQueue = SimpleQueue()
_workers: List[threading.Thread] = []
_local = threading.local()


def _work() -> None:
    _local.inside = True
    while True:
        job = _jobs.get()
        job()


def _run_queued() -> None:
    """Run jobs from the queue in the calling thread until it is empty."""
    was, _local.inside = getattr(_local, "inside", False), True
    try:
        while True:
            try:
                job = _jobs.get_nowait()
            except Empty:
                return
            job()
    finally:
        _local.inside = was


def thread_map(fn: Callable[[T], R], items: Iterable[T]) -> List[R]:
    """``[fn(x) for x in items]``, in that order, computed on threads when there are some.

    >>> thread_map(lambda x: x * x, range(5))
    [0, 1, 4, 9, 16]
    """
    items = list(items)
    threads = max(1, cv2.getNumThreads())
    if threads == 1 or len(items) < 2 or getattr(_local, "inside", False):
        return [fn(x) for x in items]
    while len(_workers) < threads - 1:  # the calling thread is the last one
        worker = threading.Thread(target=_work, name=f"scalematch-{len(_workers)}", daemon=True)
        worker.start()
        _workers.append(worker)
    results: List = [None] * len(items)
    errors: List[BaseException] = []
    # a queue, not a threading.Semaphore: a Ctrl-C that lands inside a Semaphore's Condition
    # wait can leave its lock released twice, and "RuntimeError: release unlocked lock" then
    # stands where the KeyboardInterrupt was; SimpleQueue.get raises it as it is
    done: SimpleQueue = SimpleQueue()

    def job(k: int) -> Callable[[], None]:
        def run() -> None:
            try:
                results[k] = fn(items[k])
            except BaseException as exc:  # noqa: BLE001 (raised again in the calling thread)
                errors.append(exc)
            finally:
                done.put(k)
        return run

    for k in range(len(items)):
        _jobs.put(job(k))
    _run_queued()
    for _ in items:
        done.get()
    if errors:
        raise errors[0]
    return results
