"""Threads for independent work: the same answers in the same order, errors raised, no
self-waiting when nested."""

from __future__ import annotations

import threading

import cv2
import pytest

from scalematch.stages.threads import thread_map


@pytest.fixture(params=[1, 2, 3])
def cv_threads(request):
    before = cv2.getNumThreads()
    cv2.setNumThreads(request.param)
    yield request.param
    cv2.setNumThreads(before)


def test_results_come_in_order(cv_threads):
    assert thread_map(lambda x: x * 10, range(20)) == [10 * x for x in range(20)]
    assert thread_map(str, []) == []


def test_the_work_is_spread_over_threads_when_opencv_has_several():
    before = cv2.getNumThreads()
    cv2.setNumThreads(2)
    barrier = threading.Barrier(2, timeout=10)  # passes only if two pieces run at once
    try:
        names = thread_map(lambda _: (barrier.wait(), threading.current_thread().name)[1],
                           range(2))
    finally:
        cv2.setNumThreads(before)
    assert len(set(names)) == 2


def test_one_opencv_thread_means_the_calling_thread_only():
    before = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        names = thread_map(lambda _: threading.current_thread().name, range(4))
    finally:
        cv2.setNumThreads(before)
    assert set(names) == {threading.current_thread().name}


def test_an_error_in_a_piece_is_raised_in_the_caller(cv_threads):
    def piece(x):
        if x == 3:
            raise ValueError("piece 3")
        return x

    with pytest.raises(ValueError, match="piece 3"):
        thread_map(piece, range(6))
    assert thread_map(lambda x: x, range(6)) == list(range(6))  # the threads still serve


def test_nested_maps_run_serially_and_finish(cv_threads):
    out = thread_map(lambda x: sum(thread_map(lambda y: x * y, range(4))), range(5))
    assert out == [6 * x for x in range(5)]


def test_a_keyboard_interrupt_in_a_piece_is_raised_as_itself(cv_threads):
    def piece(x):
        if x == 3:
            raise KeyboardInterrupt
        return x

    with pytest.raises(KeyboardInterrupt):
        thread_map(piece, range(8))
    assert thread_map(lambda x: x + 1, range(4)) == [1, 2, 3, 4]  # the pool still works
