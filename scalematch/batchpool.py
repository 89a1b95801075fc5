"""A batch's pairs run on this machine: ``run_serial``, one after the other in this process (the
pairs left go to a worker process once one runs out of memory), and ``run_pool``, on worker
processes of its own, one pair each at a time. A worker killed (out of memory) is replaced and
its pair tried again (``after_worker_death`` says when to give one up); a worker that had an
internal error is replaced before it takes another pair; every worker dies with the main
process, even by ``kill -9`` (``die_with_parent``).
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import multiprocessing.connection
import os
import signal
import sys
import threading
import time
from typing import Any, Callable, Dict, Iterable, Iterator, List, Optional, Set, Tuple

from .batch import INTERNAL, Pair, bounded, error_line, match_pair
from .config import Config
from .imageio import catch_decoder_stderr
from .pipeline import warm_up_blas

#: How often a worker checks that the process that started it is still alive, s (where
#: PR_SET_PDEATHSIG is not available: not on Linux).
PARENT_POLL_S = 0.5
#: Linux prctl option: signal this process when its parent dies (<linux/prctl.h>).
PR_SET_PDEATHSIG = 1
#: Deaths of a pair's worker process (killed by the system: out of memory, SIGKILL; a crash or
#: an exit in native code) before the pair gets an error line instead of another try. The
#: out-of-memory killer ends the largest process, not the one that asked last, so the first
#: death may be another pair's doing or a passing shortage of memory: the pair is tried again
#: alone. A second death while it ran alone is its own; a third try would cost another worker
#: start for nothing.
MAX_WORKER_DEATHS_PER_PAIR = 2
#: BLAS threads of a worker process, where the user set none: the processes are the parallelism
#: (as OpenCV's one thread in ``_init_worker``). BLAS reads them when numpy loads, which a
#: spawned worker does before any of its code runs, so they are put in the environment the
#: worker starts with (``worker_environment``).
WORKER_BLAS_THREADS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
#: How long a worker that was told to end (or has ended) is waited for before it is killed, s.
WORKER_EXIT_WAIT_S = 5.0


def run_serial(pairs: Iterable[Pair], config: Config, max_pixels: int) -> Iterator[Dict[str, Any]]:
    """The lines of ``pairs``, matched one after the other in this process, until a pair has an
    internal error (out of memory): the pairs left then go to a worker process (``run_pool``,
    one worker), as this one may not have its memory back (under a memory limit the next pair
    failed too, and the process then crashed in native code)."""
    todo = iter(pairs)
    for pair in todo:
        line = match_pair(pair, config, max_pixels)
        yield line
        if line.get("error_kind") == INTERNAL:
            yield from run_pool(todo, config, max_pixels, 1)
            return


def after_worker_death(pair: Pair, deaths: int, config: Config,
                       max_deaths: int = MAX_WORKER_DEATHS_PER_PAIR,
                       how: str = "") -> Optional[Dict[str, Any]]:
    """What becomes of ``pair`` when its worker process died: None to submit it again (its
    ``deaths``-th death is not yet ``max_deaths``), else its internal error line; ``how`` is how
    the worker ended the last time ("killed by SIGKILL", "exit code 1")."""
    if deaths < max_deaths:
        return None
    last = f", the last one {how}" if how else ""
    return error_line(pair, f"internal error, its worker process died while matching it, "
                            f"{deaths} times{last} (killed by the system, e.g. out of memory, or "
                            f"a crash); try the pair alone: scalematch LOW HIGH", config,
                      kind=INTERNAL)


def _watch_parent(parent_pid: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


def die_with_parent(parent_pid: int) -> None:
    """End this process when ``parent_pid`` (its parent) ends, even by ``kill -9``.

    On Linux the kernel sends SIGKILL on the parent's death (prctl PR_SET_PDEATHSIG); elsewhere,
    and as a second guard, a daemon thread polls ``os.getppid()`` (a process whose parent died
    is handed to another one).
    """
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:  # the parent died before we asked
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent_pid,), name="scalematch-parent-watch",
                     daemon=True).start()


@contextlib.contextmanager
def worker_environment() -> Iterator[None]:
    """``os.environ`` with ``WORKER_BLAS_THREADS`` added where unset, for the worker processes
    started inside; as it was, after."""
    added = [name for name in WORKER_BLAS_THREADS if name not in os.environ]
    for name in added:
        os.environ[name] = WORKER_BLAS_THREADS[name]
    try:
        yield
    finally:
        for name in added:
            os.environ.pop(name, None)


def _init_worker(parent_pid: int) -> None:
    """Worker set-up: die with the main process; one OpenCV thread (the processes are the
    parallelism; its BLAS threads are set as it starts, ``worker_environment``); Ctrl-C is left
    to the main process, which stops the workers; BLAS's buffers taken while memory is there
    (``warm_up_blas``)."""
    import cv2

    die_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    cv2.setNumThreads(1)
    catch_decoder_stderr()  # its stderr is its own: the decoders' words go in the pair's line
    warm_up_blas()


def _worker_main(conn: Any, parent_pid: int, task: Callable[..., Dict[str, Any]]) -> None:
    """A worker process: ``task(pair, config, max_pixels)`` for each (pair, config, max_pixels)
    received on ``conn``, its line sent back, until None or the main process closes the pipe.
    After a line with an internal error (out of memory) it ends: memory a ``MemoryError`` left
    taken, or a library left in a bad state, must not fail the next pair, which a fresh process
    takes."""
    _init_worker(parent_pid)
    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError):  # the main process closed the pipe, or died (kill -9)
            return
        if job is None:
            return
        line = task(*job)
        try:
            conn.send(line)
        except OSError:  # died while this pair was matched: nobody to tell (no traceback)
            return
        if line.get("error_kind") == INTERNAL:
            return


class _Worker:
    """A worker process of ``run_pool`` and the main process's end of its pipe. Hashable by
    identity: it stands for the pair it holds as a future would."""

    def __init__(self, task: Callable[..., Dict[str, Any]]) -> None:
        ctx = multiprocessing.get_context("spawn")  # no fork after OpenCV threads start
        self.conn, child = ctx.Pipe()
        self.process = ctx.Process(target=_worker_main, args=(child, os.getpid(), task),
                                   name="scalematch-worker", daemon=True)
        with worker_environment():
            self.process.start()
        child.close()  # the worker's end: EOF here when the worker ends

    def line(self) -> Optional[Dict[str, Any]]:
        """The line the worker sent, or None when it ended without one (killed, crashed)."""
        try:
            if self.conn.poll():  # what it sent before it ended is still in the pipe
                return self.conn.recv()
        except (EOFError, OSError):
            pass
        return None

    def exit_code(self, timeout: float = WORKER_EXIT_WAIT_S) -> Optional[int]:
        """The worker's exit code (negative: the signal that killed it), once it ends; it is
        killed when it has not ended within ``timeout`` seconds."""
        self.process.join(timeout)
        if self.process.exitcode is None:
            self.process.kill()
            self.process.join()
        return self.process.exitcode

    def close(self, stop_now: bool = False) -> None:
        """End the worker: at once (``stop_now``: SIGTERM, mid-pair), else after its pair."""
        if stop_now:
            self.process.terminate()
        else:
            try:
                self.conn.send(None)
            except OSError:  # it is gone already
                pass
        self.exit_code()
        self.conn.close()


def _how_it_ended(code: Optional[int]) -> str:
    """An exit code in words: "exit code 1", "killed by SIGKILL"."""
    if code is not None and code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


def run_pool(pairs: Iterable[Pair], config: Config, max_pixels: int, jobs: int,
             task: Optional[Callable[..., Dict[str, Any]]] = None) -> Iterator[Dict[str, Any]]:
    """The lines of ``pairs``, matched by ``jobs`` worker processes, in the order they finish;
    ``task`` is what a worker runs for a pair (``match_pair``, a picklable stand-in in tests).

    Each worker is a process of its own with a pipe to this one, and holds one pair at a time,
    so what becomes of a pair is known from its own worker. A worker that had an internal error
    (out of memory) ends after its line and a fresh one takes the next pair. A worker that ends
    without a line (killed by the system for memory, SIGKILL, a crash or an ``exit`` in native
    code, whatever its exit code) is replaced and its pair tried again alone, no other pair
    beside it; a pair whose worker died MAX_WORKER_DEATHS_PER_PAIR times gets an internal error
    line (``after_worker_death``), never a "no match". Workers die with this process
    (``die_with_parent``); when the iteration stops early (Ctrl-C, or the consumer closes it)
    they are terminated at once and the pairs they held get no line, so a resumed batch redoes
    them. No ``multiprocessing`` queue or lock is made: nothing of the batch is left for the
    resource tracker to clean up (and warn about) after ``kill -9``.
    """
    pool = _Pool(match_pair if task is None else task, config)
    try:
        yield from bounded(pairs, submit=lambda pair: pool.submit(pair, max_pixels),
                           wait_first=_wait_first, outcome=pool.outcome,
                           limit=lambda: 1 if pool.retrying else jobs, stop=pool.stop)
    finally:
        pool.close()


def _wait_first(workers: List[_Worker]) -> List[_Worker]:
    """Those of ``workers`` that sent a line or ended, once one has (``bounded``'s wait)."""
    ready = set(multiprocessing.connection.wait(
        [w.conn for w in workers] + [w.process.sentinel for w in workers]))
    return [w for w in workers if w.conn in ready or w.process.sentinel in ready]


class _Pool:
    """The worker processes of ``run_pool`` and what it knows of them: the idle ones, the busy
    ones, and the pairs whose worker died (how many times; those not finished yet, which run
    alone). Its methods are ``bounded``'s submit, outcome and stop."""

    def __init__(self, task: Callable[..., Dict[str, Any]], config: Config) -> None:
        self.task, self.config = task, config
        self.idle: List[_Worker] = []  # started, holding no pair
        self.busy: Set[_Worker] = set()
        self.deaths: Dict[Tuple[str, str], int] = {}  # pair -> its worker's deaths while on it
        self.retrying: Set[Tuple[str, str]] = set()  # its worker died, not yet finished

    def submit(self, pair: Pair, max_pixels: int) -> _Worker:
        """Hand ``pair`` to an idle worker, or a new one; the worker stands for the pair."""
        while True:
            worker = self.idle.pop() if self.idle else _Worker(self.task)
            try:
                worker.conn.send((pair, self.config, max_pixels))
                break
            except OSError:  # it ended while idle (killed): another one
                worker.close(stop_now=True)
        self.busy.add(worker)
        return worker

    def outcome(self, worker: _Worker, pair: Pair) -> Optional[Dict[str, Any]]:
        """The line of ``pair`` from its ``worker``, which sent it or ended; None to submit the
        pair again. A worker that had an internal error ends (a fresh one takes the next
        pair); one that sent a line waits for the next."""
        self.busy.discard(worker)
        line = worker.line()
        if line is None:
            return self._died(worker, pair)
        self.retrying.discard(pair.key)
        if line.get("error_kind") == INTERNAL:
            worker.close()  # it ends by itself: a fresh one takes the next pair
        else:
            self.idle.append(worker)
        return line

    def _died(self, worker: _Worker, pair: Pair) -> Optional[Dict[str, Any]]:
        """``worker`` ended without the line of ``pair``: count the death; None to try the pair
        again (alone), else its internal error line (``after_worker_death``)."""
        code = worker.exit_code()
        worker.close(stop_now=True)
        self.deaths[pair.key] = self.deaths.get(pair.key, 0) + 1
        line = after_worker_death(pair, self.deaths[pair.key], self.config,
                                  how=_how_it_ended(code))
        if line is None:
            self.retrying.add(pair.key)
        else:
            self.retrying.discard(pair.key)
        return line

    def stop(self, workers: List[_Worker]) -> None:
        """End ``workers`` at once, mid-pair (the iteration stopped early)."""
        for worker in workers:
            self.busy.discard(worker)
            worker.close(stop_now=True)

    def close(self) -> None:
        """End every worker: the busy ones at once, the idle ones after telling them."""
        for worker in list(self.busy):
            worker.close(stop_now=True)
        for worker in self.idle:
            worker.close()
