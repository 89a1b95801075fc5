"""Batch matching: many pairs from a CSV, one JSON line each, resumable, on a local process pool
or a Dask cluster.

Here, what every part of a batch shares: ``Pair`` (a row of the CSV), ``BatchError``, the line
of one pair (``match_pair``: one pair -> one JSON line, never raises; ``error_line``),
``Counts`` (the lines written, by verdict) and ``bounded``, the loop of every runner: it yields
the lines in the order pairs finish and keeps at most a few pairs per worker in flight, so the
main process stays the same size however many pairs there are (docs/results/BATCH.md).

The parts, in the order a run uses them: the pairs CSV (:mod:`scalematch.batchcsv`:
``read_rows``, ``unique_pairs``); the output file an earlier run left, checked and resumed
(:mod:`scalematch.batchresume`: ``scan_output``, ``resume_output``, ``plan_run``); the runners,
in this process or on worker processes of its own (:mod:`scalematch.batchpool`: ``run_serial``,
``run_pool``) or on a Dask cluster (:mod:`scalematch.batchdask`: ``run_dask``).
:mod:`scalematch.batchrun` runs them for the command line.

Errors here are ``BatchError`` (a ``ValueError``) with a one-line message; the command line turns
them into exit code 2.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any, Callable, Dict, Hashable, Iterable, Iterator, List, Tuple

from .config import Config
from .errors import internal_error, interrupted
from .greylevels import grey_of_file
from .pipeline import match
from .result import error_record
from .working import read_pair

#: ``error_kind`` of an error line: the pair's files or values (a ``ValueError``: missing file,
#: bad image, too small) or an unexpected error (out of memory, a bug, a worker killed).
INPUT, INTERNAL = "input", "internal"


class BatchError(ValueError):
    """A batch cannot start (bad CSV, unusable output file, no scheduler); one-line message."""


@dataclass(frozen=True)
class Pair:
    """One row of the pairs CSV."""

    low: str  #: the low-resolution image's path as written in the CSV (its line's key)
    high: str  #: the high-resolution image's path as written in the CSV
    low_file: str  #: the file read: a relative path is taken from the CSV's folder
    high_file: str
    #: the row's other columns of a CSV with a header, (name, value) in the CSV's order: the
    #: line carries them as ``"csv"`` (an expected ratio, an id), so a script needs no join
    columns: Tuple[Tuple[str, str], ...] = ()

    @property
    def key(self) -> Tuple[str, str]:
        """(low, high) as written: what identifies the pair's line in the output."""
        return (self.low, self.high)


@dataclass(frozen=True)
class Counts:
    """The lines a run wrote, by what they say."""

    matched: int = 0
    no_match: int = 0  #: lines with no reliable match
    errors: int = 0  #: error lines
    internal: int = 0  #: of the error lines, unexpected errors (``error_kind`` ``INTERNAL``)

    @property
    def lines(self) -> int:
        """All the lines counted."""
        return self.matched + self.no_match + self.errors

    def add(self, line: Dict[str, Any]) -> "Counts":
        """These counts with the result line ``line`` counted too."""
        kind = "errors" if "error" in line else "matched" if line["matched"] else "no_match"
        return replace(self, internal=self.internal + (line.get("error_kind") == INTERNAL),
                       **{kind: getattr(self, kind) + 1})


# --------------------------------------------------------------------------- one pair

def error_line(pair: Pair, error: str, config: Config, seconds: float = 0.0,
               kind: str = INPUT) -> Dict[str, Any]:
    """The line of a pair that could not be matched (docs/GUIDE.md, "JSON"); ``kind`` is
    ``INPUT`` or ``INTERNAL`` (whose message then starts "internal error")."""
    return with_columns(error_record(pair.low, pair.high, error, kind, config, seconds), pair)


def with_columns(line: Dict[str, Any], pair: Pair) -> Dict[str, Any]:
    """``line`` with the CSV row's other columns as ``"csv"`` (name -> text), when it had any."""
    return dict(line, csv=dict(pair.columns)) if pair.columns else line


def match_pair(pair: Pair, config: Config, max_pixels: int) -> Dict[str, Any]:
    """The batch line of ``pair``: the JSON of its match, or an error line; never raises."""
    t0 = time.perf_counter()
    try:
        low, high = read_pair(pair.low_file, pair.high_file, config, max_pixels)
        result = match(grey_of_file(low.image, pair.low_file),
                       grey_of_file(high.image, pair.high_file), config,
                       decoded_factors=(low.factor, high.factor))
        return with_columns(result.to_dict(pair.low, pair.high, low.shape, high.shape,
                                           (low.warning, high.warning)), pair)
    except ValueError as exc:  # ImageError included: a bad image, too small, constant
        error, kind = str(exc), INPUT
    except Exception as exc:  # noqa: BLE001 (a pair must never stop the batch; MemoryError too)
        if interrupted(exc):  # Ctrl-C, worn by a library's error: it stops the batch
            raise KeyboardInterrupt from exc
        error, kind = internal_error(exc), INTERNAL
    return error_line(pair, error, config, time.perf_counter() - t0, kind)


# --------------------------------------------------------------------------- bounded in-flight

def bounded(pairs: Iterable[Pair], submit: Callable[[Pair], Hashable],
            wait_first: Callable[[List[Any]], Iterable[Any]],
            outcome: Callable[[Any, Pair], Dict[str, Any]], limit: Callable[[], int],
            stop: Callable[[List[Any]], None]) -> Iterator[Dict[str, Any]]:
    """Submit ``pairs`` with at most ``limit()`` unfinished at once; yield each line as its pair
    finishes. ``wait_first(futures)`` blocks until at least one is done and returns the done;
    ``outcome(future, pair)`` is the pair's line, or None to submit the pair again (before any
    new pair); ``stop(futures)`` is given the unfinished ones if the iteration ends early
    (Ctrl-C)."""
    todo = iter(pairs)
    again: List[Pair] = []  # to submit again, oldest first
    pending: Dict[Any, Pair] = {}
    more = True
    try:
        while True:
            room = max(limit(), 1) - len(pending)
            while room > 0 and (again or more):
                pair = again.pop(0) if again else next(todo, None)
                if pair is None:
                    more = False
                else:
                    pending[submit(pair)] = pair
                    room -= 1
            if not pending:
                return
            done = set(wait_first(list(pending)))
            for future in [f for f in pending if f in done]:  # in the order submitted
                pair = pending.pop(future)
                line = outcome(future, pair)
                if line is None:
                    again.append(pair)
                else:
                    yield line
    finally:
        if pending:
            stop(list(pending))
