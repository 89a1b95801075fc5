"""Batch matching: many pairs from a CSV, one JSON line each, resumable, on a local process pool
or a Dask cluster.

In the order a run uses them: ``read_rows`` (the CSV -> (low, high, other columns) rows),
``unique_pairs`` (repeated rows matched once, paths resolved), ``scan_output`` (what an
earlier run left in the output file: the pairs done and which of them errored; it refuses a
file holding anything but result lines, or results made with another configuration),
``drop_error_lines`` (with
``--retry-errors``: the error lines of pairs to match again removed, the file replaced in one
step; ``resume_output`` does this or cuts a torn last line), ``plan_run`` (the ``Plan``: the
pairs to match, those skipped, those retried), ``Counts`` (the lines written, by verdict),
``match_pair`` (one pair -> one JSON line, never raises), and the runners ``run_serial``,
``run_pool`` and ``run_dask``: each yields the lines in the order pairs finish and keeps at most
a few pairs per worker in flight, so the main process stays the same size however many pairs
there are (docs/BATCH.md). ``run_pool``'s workers are processes of its own, one pair each at a
time: a worker killed (out of memory) is replaced and its pair tried again
(``after_worker_death`` says when to give one up), and a worker that had an internal error is
replaced before it takes another pair.

Errors here are ``BatchError`` (a ``ValueError``) with a one-line message; the command line turns
them into exit code 2.
"""

from __future__ import annotations

import contextlib
import ctypes
import csv
import json
import multiprocessing
import multiprocessing.connection
import os
import re
import signal
import sys
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import (Any, Callable, Collection, Dict, FrozenSet, Hashable, Iterable, Iterator,
                    List, Optional, Sequence, Set, Tuple)

from .config import Config
from .errors import internal_error, interrupted
from .imageio import catch_decoder_stderr, grey_of_file
from .pipeline import match, warm_up_blas
from .result import dumps, error_record, to_jsonable
from .working import read_pair

#: Header names of the two path columns; a column named exactly so wins, else the one column
#: whose name starts with it ("low_path", "high-res", ...). Any other columns are ignored.
COLUMNS = ("low", "high")
#: A first-row cell holding one of these is a path, so the row is data, not a header.
PATH_CHARS = "./\\"
#: Pairs submitted per worker and not yet finished: 2 keeps a worker busy while the main process
#: writes the line of the pair it just finished, and bounds the main process's memory.
IN_FLIGHT_PER_WORKER = 2
#: How often a worker checks that the process that started it is still alive, s (where
#: PR_SET_PDEATHSIG is not available: not on Linux).
PARENT_POLL_S = 0.5
#: Linux prctl option: signal this process when its parent dies (<linux/prctl.h>).
PR_SET_PDEATHSIG = 1
#: How long to try to reach a Dask scheduler before giving up, s.
DASK_CONNECT_TIMEOUT_S = 10.0
#: How often the number of Dask worker threads (hence the in-flight bound) is asked again, s.
DASK_RECHECK_S = 5.0
#: The start of every line ``dumps`` writes: a last line torn by an interruption starts so too.
LINE_START = b'{"'
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
#: ``error_kind`` of an error line: the pair's files or values (a ``ValueError``: missing file,
#: bad image, too small) or an unexpected error (out of memory, a bug, a worker killed).
INPUT, INTERNAL = "input", "internal"
#: Schemes of a Dask scheduler address (distributed's comm backends; ``inproc`` for a cluster
#: in this process) and the form of an address: scheme://host:port, or host:port (tcp).
DASK_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")
DASK_ADDRESS = re.compile(r"^(?:(?P<scheme>[a-z]+)://)?(?P<host>\[[0-9a-fA-F:.]+\]|[^\s:/\[\]]+)"
                          r":(?P<port>[0-9]{1,5})/?$")


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
class Done:
    """What an earlier run left in the output file."""

    pairs: FrozenSet[Tuple[str, str]]  #: (low, high) of every complete result line
    errors: FrozenSet[Tuple[str, str]]  #: those whose line holds an "error"
    complete_bytes: int  #: length of the complete lines; anything after it was torn


NOTHING_DONE = Done(frozenset(), frozenset(), 0)


# --------------------------------------------------------------------------- the pairs CSV

def _column(cells: Sequence[str], name: str, path: Path) -> int:
    exact = [i for i, c in enumerate(cells) if c == name]
    named = exact or [i for i, c in enumerate(cells) if c.startswith(name)]
    if len(named) == 1:
        return named[0]
    found = "several columns" if named else "no column"
    raise BatchError(f"{path}: the header {','.join(cells)} has {found} named {name!r}; "
                     f"name one column low and one high")


def _header(row: Sequence[str], path: Path) -> Optional[Tuple[int, int]]:
    """(low column, high column) if ``row`` is a header naming them, None if it is data."""
    cells = [c.strip().lower() for c in row]
    if any(ch in c for c in cells for ch in PATH_CHARS):
        return None
    if not any(c.startswith(COLUMNS) for c in cells):
        return None
    return _column(cells, "low", path), _column(cells, "high", path)


def _looks_like_names(cells: Sequence[str], base: Path) -> bool:
    """A first row of names rather than paths: two cells or more, none holding a path
    character or naming a file (from ``base``, the CSV's folder), some holding a letter
    (``id,expected``)."""
    return len(cells) >= 2 and not any(ch in c for c in cells for ch in PATH_CHARS) and \
        any(any(ch.isalpha() for ch in c) for c in cells) and \
        not any((base / c).exists() for c in cells if c)


def _trimmed(row: Sequence[str]) -> List[str]:
    """The cells of a row without the empty ones at its end (spreadsheets add them)."""
    cells = [c.strip() for c in row]
    while cells and not cells[-1]:
        cells.pop()
    return cells


def read_rows(path: Path) -> List[Tuple[str, str, Tuple[Tuple[str, str], ...]]]:
    """The (low, high, other columns) rows of a pairs CSV, in file order, repeated rows
    included; the other columns, (name, value) from the header, only with one.

    A file without header has exactly two columns, low then high. A header row names the columns:
    ``low`` and ``high`` (or names starting so, such as ``low_path,high_path``), in any position,
    among any others (``name,low,high``). Blank rows are skipped; anything else that is not a
    pair of paths raises ``BatchError`` naming the line.
    """
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = [(n, _trimmed(r)) for n, r in enumerate(csv.reader(fh), 1)]
    except UnicodeDecodeError:
        raise BatchError(f"{path} is not a text file (an image?); give a CSV with columns "
                         f"low,high, one pair of image paths a line") from None
    except (OSError, csv.Error) as exc:
        raise BatchError(f"cannot read {path}: {exc}; give a CSV with columns low,high")
    rows = [(n, r) for n, r in rows if r]
    columns = _header(rows[0][1], path) if rows else None
    if rows and columns is None and _looks_like_names(rows[0][1], Path(path).parent):
        n, cells = rows[0]
        raise BatchError(f"{path} line {n} ({','.join(cells)}) reads as a header, but names no "
                         f"columns low and high: name them so (low,high), or give image paths")
    names: List[str] = []
    if columns is not None:
        names = [c.strip() for c in rows[0][1]]
        rows = rows[1:]
    pairs = []
    for n, cells in rows:
        if columns is None and len(cells) != 2:
            plural = "" if len(cells) == 1 else "s"
            raise BatchError(f"{path} line {n} has {len(cells)} column{plural}; without a header "
                             f"a pairs CSV has two, low,high (or name the columns low and high "
                             f"in a header row)")
        lo, hi = columns or (0, 1)
        low = cells[lo] if lo < len(cells) else ""
        high = cells[hi] if hi < len(cells) else ""
        if not low or not high:
            raise BatchError(f"{path} line {n} does not have two paths low,high")
        others = tuple((name, cells[i] if i < len(cells) else "")
                       for i, name in enumerate(names) if columns and i not in columns and name)
        pairs.append((low, high, others))
    return pairs


def _resolve(path: str, base: Path) -> str:
    p = Path(path).expanduser()
    return str(p if p.is_absolute() else base / p)


def unique_pairs(rows: Iterable[Tuple], base: Path) -> List[Pair]:
    """One ``Pair`` per distinct (low, high) row, in first-seen order (with that row's other
    columns, when ``rows`` are :func:`read_rows`'s); relative paths from ``base`` (the CSV's
    folder). A repeated row would write a second line for the same key."""
    seen = set()
    pairs = []
    for low, high, *rest in rows:
        if (low, high) not in seen:
            seen.add((low, high))
            pairs.append(Pair(low, high, _resolve(low, base), _resolve(high, base),
                              tuple(rest[0]) if rest else ()))
    return pairs


# --------------------------------------------------------------------------- the output file

def config_json(config: Config) -> Dict[str, Any]:
    """``config`` as a result line records it (a JSON object)."""
    return json.loads(dumps(to_jsonable(config)))


def _flat(obj: Any, prefix: str = "") -> Dict[str, Any]:
    if not isinstance(obj, dict):
        return {prefix: obj}
    out: Dict[str, Any] = {}
    for k, v in obj.items():
        out.update(_flat(v, f"{prefix}.{k}" if prefix else str(k)))
    return out


#: The command-line option that sets each recorded parameter directly (``scalematch match
#: --help``); any other parameter is said as ``--set PATH=VALUE``
#: (the threshold options too: ``options.THRESHOLD_OPTIONS``, which a test keeps in step)
OPTION_OF_PATH = {"model": "--model", "seed": "--seed", "order": "--order",
                  "time_budget_s": "--time-budget", "nodata.rule": "--nodata",
                  "harris.threshold": "--harris-threshold",
                  "harris_low.threshold": "--harris-threshold", "matcher.ratio": "--ratio-test",
                  "ransac.threshold_px": "--ransac-threshold",
                  "ransac.max_iters": "--ransac-iterations",
                  "decision.min_inliers": "--min-inliers", "decision.max_log_nfa": "--max-log-nfa"}


def _option_text(path: str, value: Any) -> str:
    """One recorded parameter as the option that gives it (``--model homography``,
    ``--no-views``, ``--set ransac.threshold_px=2.0``)."""
    if path == "views.enabled":
        return "--views" if value else "--no-views"
    if path == "scales" and isinstance(value, list):
        return "--scales " + ",".join(f"{s:g}" for s in value)
    if path in ("low_max_side", "high_max_side"):
        return f"--working-size {value or 0}"
    text = value if isinstance(value, str) else json.dumps(value)
    if path in OPTION_OF_PATH:
        return f"{OPTION_OF_PATH[path]} {text}"
    return f"--set {path}={text}"


def options_of(recorded: Dict[str, Any]) -> List[str]:
    """The matching options that give the recorded configuration ``recorded`` (a result line's
    ``config``), as a user types them: its mode, then what differs from that mode's defaults on
    the command line (where tilted views are on unless ``--no-views``).

    >>> options_of(config_json(Config.preset("paper")))
    ['--mode paper', '--no-views']
    >>> options_of(config_json(replace(Config(), model="homography")))
    ['--model homography']
    """
    mode = recorded.get("mode", "default")
    try:
        base = Config.preset(mode)
    except ValueError:
        base = Config()
    base = replace(base, views=replace(base.views, enabled=True))  # the command line's default
    a, b = _flat(config_json(base)), _flat(recorded)
    said = [] if mode == "default" else [f"--mode {mode}"]
    for k in sorted(set(a) | set(b)):
        if k == "mode" or a.get(k) == b.get(k) or k not in b:
            continue
        text = _option_text(k, b[k])
        if text not in said:
            said.append(text)
    return said


def _differing_options(recorded: Dict[str, Any], now: Dict[str, Any]) -> str:
    """What a batch output's options and this run's differ by, in options as typed: "made
    with --mode paper; this run: no matching options"."""
    then, this = options_of(recorded), options_of(now)
    gone = [o for o in then if o not in this]
    new = [o for o in this if o not in then]
    return (f"made with {' '.join(gone) or 'no matching options'}; this run: "
            f"{' '.join(new) or 'no matching options'}")


def _result_key(line: bytes) -> Optional[Tuple[Tuple[str, str], Dict[str, Any]]]:
    """((low, high) as given in the CSV, object) of a batch result line, None for anything else.

    A line's ``low``/``high`` are the coarser and the finer image as found: with ``order``
    "swapped" they are the CSV's high and low.
    """
    try:
        obj = json.loads(line)
        key = (obj["low"]["path"], obj["high"]["path"])
        if obj.get("order") == "swapped":
            key = key[::-1]
    except (ValueError, KeyError, TypeError, AttributeError):
        return None
    if not all(isinstance(p, str) for p in key) or not ("error" in obj or "matched" in obj):
        return None
    return key, obj


def _result_lines(fh: Any, path: Path, config: Dict[str, Any]
                  ) -> Iterator[Tuple[bytes, Optional[Tuple[str, str]], bool]]:
    """(line, its (low, high) or None when blank, whether it is an error) of every complete line
    of the open batch output ``fh``; stops before a torn last line. Raises ``BatchError`` at a
    line that is not a result of configuration ``config`` (see ``scan_output``)."""
    for n, line in enumerate(fh, 1):
        if not line.endswith(b"\n") and line.startswith(LINE_START):
            return  # torn by an interruption: the only line that may end so
        if not line.strip():
            yield line, None, False
            continue
        found = _result_key(line)
        if found is None:
            raise BatchError(
                f"{path} line {n} is not a scalematch result; the output file must "
                f"be new or the output of an earlier batch (left unchanged)")
        key, obj = found
        if "config" in obj and obj["config"] != config:
            raise BatchError(
                f"{path} holds results made with other options "
                f"({_differing_options(obj['config'], config)}); resume with the same "
                f"options or write to another file")
        yield line, key, "error" in obj


def scan_output(path: Path, config: Dict[str, Any]) -> Done:
    """What the batch output ``path`` already holds, read without changing it.

    Every line must be a result line of a run with configuration ``config`` (``config_json``):
    anything else raises ``BatchError``, so a file that is not a batch output (notes, the pairs
    CSV) is never appended to, and results of other options are never mixed in. Blank lines are
    allowed. A last line without its newline, starting as result lines start, was torn by an
    interruption: it is not counted (``cut_torn_line`` removes it).
    """
    if not path.is_file():
        return NOTHING_DONE
    try:
        with open(path, "rb") as fh:
            return _tally(_result_lines(fh, path, config))
    except OSError as exc:
        raise BatchError(f"cannot read {path}: {exc.strerror or exc}")


def _tally(lines: Iterable[Tuple[bytes, Optional[Tuple[str, str]], bool]]) -> Done:
    """What the lines of ``_result_lines`` hold: the pairs done, those errored, their length."""
    pairs, errors = set(), set()
    complete = 0
    for line, key, error in lines:
        if key is not None:
            pairs.add(key)
            if error:
                errors.add(key)
        complete += len(line)
    return Done(frozenset(pairs), frozenset(errors), complete)


def cut_torn_line(path: Path, done: Done) -> None:
    """Remove what follows the complete lines of ``path`` (a line torn by an interruption)."""
    if path.is_file() and path.stat().st_size > done.complete_bytes:
        os.truncate(path, done.complete_bytes)


def drop_error_lines(path: Path, keys: Collection[Tuple[str, str]],
                     config: Dict[str, Any]) -> Done:
    """Remove from the batch output ``path`` the error lines of the pairs ``keys`` (to match them
    again) and a torn last line; every other line is kept, byte for byte and in order. Returns
    what the file holds then (``scan_output``).

    The kept lines go to a temporary file in the same folder, which is flushed to disk and then
    put in the place of ``path`` in one step (``os.replace``): an interruption at any moment
    leaves the old file or the new one, never a part. The file keeps its permissions. Raises
    ``BatchError`` as ``scan_output`` does, or when the folder is not writable (``path`` is then
    unchanged).
    """
    import stat
    import tempfile

    target = Path(os.path.realpath(path))  # a symbolic link stays one
    tmp = None
    try:
        with open(target, "rb") as src, tempfile.NamedTemporaryFile(
                "wb", dir=target.parent, prefix=f".{target.name}.", suffix=".tmp",
                delete=False) as dst:
            tmp = dst.name
            kept = (item for item in _result_lines(src, path, config)
                    if not (item[2] and item[1] in keys))
            done = _tally(_written(dst, kept))  # streamed: a line at a time in memory
            dst.flush()
            os.fsync(dst.fileno())
            os.chmod(tmp, stat.S_IMODE(os.fstat(src.fileno()).st_mode))
        os.replace(tmp, target)
        tmp = None
        _fsync_folder(target.parent)
    except OSError as exc:
        raise BatchError(f"cannot rewrite {path} without its error lines: "
                         f"{exc.strerror or exc} (left unchanged)")
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
    return done


def _written(fh: Any, lines: Iterable[Tuple[bytes, Any, bool]]
             ) -> Iterator[Tuple[bytes, Any, bool]]:
    """``lines`` (as ``_result_lines`` gives them), each written to ``fh`` as it passes."""
    for item in lines:
        fh.write(item[0])
        yield item


def _fsync_folder(folder: Path) -> None:
    """Flush the folder's entries to disk (a renamed file survives a power cut); not on Windows."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


# --------------------------------------------------------------------------- what a run does

def errors_to_retry(done: Done, pairs: Iterable[Pair]) -> FrozenSet[Tuple[str, str]]:
    """The pairs of ``pairs`` whose line in the output is an error (``--retry-errors``): an
    error line of a pair no longer in the CSV stays."""
    return done.errors & {p.key for p in pairs}


def resume_output(path: Path, done: Done, retry: FrozenSet[Tuple[str, str]],
                  config: Dict[str, Any]) -> Tuple[Done, FrozenSet[Tuple[str, str]]]:
    """Make the batch output ``path`` (``done``: ``scan_output``'s reading of it) ready to
    append to: with pairs to ``retry``, their error lines removed (``drop_error_lines``), else a
    torn last line cut (``cut_torn_line``). Returns what the file holds then and the pairs to
    match again: those of ``retry`` with no good line (a pair with a good line too keeps it and
    is not redone). Call it once nothing else can refuse the run: the file is changed."""
    if retry:
        done = drop_error_lines(path, retry, config)
        return done, retry - done.pairs
    cut_torn_line(path, done)
    return done, frozenset()


@dataclass(frozen=True)
class Plan:
    """What a batch run does with the pairs of its CSV, given what its output already holds."""

    pairs: Tuple[Pair, ...]  #: the distinct pairs of the CSV, in first-seen order
    todo: Tuple[Pair, ...]  #: those to match now: without a line in the output
    repeated_rows: int  #: rows of the CSV that repeat an earlier row (matched once)
    skipped: int  #: pairs whose line is in the output already
    errors_before: int  #: of the pairs, those whose line in the output is an error
    retried: FrozenSet[Tuple[str, str]]  #: pairs whose error line was removed, matched again


def plan_run(rows: int, pairs: Sequence[Pair], done: Done = NOTHING_DONE,
             retried: FrozenSet[Tuple[str, str]] = frozenset()) -> Plan:
    """The ``Plan`` of ``pairs`` (from ``rows`` rows of the CSV) when the output holds ``done``
    (after ``resume_output``) and the error lines of ``retried`` were removed."""
    todo = tuple(p for p in pairs if p.key not in done.pairs)
    return Plan(pairs=tuple(pairs), todo=todo, repeated_rows=rows - len(pairs),
                skipped=len(pairs) - len(todo),
                errors_before=sum(p.key in done.errors for p in pairs), retried=retried)


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


def _outcome(future: Any, pair: Pair, config: Config) -> Dict[str, Any]:
    """The line of a finished future; an error line when its worker failed (died, cancelled)."""
    try:
        return future.result()
    except Exception as exc:  # noqa: BLE001 (its worker failed, not its pair's files)
        return error_line(pair, f"{internal_error(exc)} (its worker failed)", config,
                          kind=INTERNAL)


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


# --------------------------------------------------------------------------- runners

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


def check_scheduler_address(address: str) -> str:
    """``address`` when it has the form of a Dask scheduler address, else ``BatchError`` saying
    the form: scheme://host:port with a scheme of ``DASK_SCHEMES``, host:port (tcp), or an
    ``inproc://`` address (a cluster in this process). Checked before connecting, so a malformed
    address fails at once rather than after the connection's time-out.

    >>> check_scheduler_address("tcp://127.0.0.1:8786")
    'tcp://127.0.0.1:8786'
    >>> check_scheduler_address("127.0.0.1")
    Traceback (most recent call last):
    ...
    scalematch.batch.BatchError: --scheduler 127.0.0.1: no port; a Dask scheduler address is scheme://host:port, e.g. tcp://127.0.0.1:8786 (schemes: tcp, tls, ws, wss, ucx)
    """
    form = ("a Dask scheduler address is scheme://host:port, e.g. tcp://127.0.0.1:8786 "
            f"(schemes: {', '.join(DASK_SCHEMES)})")
    if address.startswith("inproc://") and len(address) > len("inproc://"):
        return address
    found = DASK_ADDRESS.match(address.strip())
    scheme = found.group("scheme") if found else address.partition("://")[0].lower() \
        if "://" in address else None
    if scheme in ("http", "https"):
        raise BatchError(f"--scheduler {address}: http is the dashboard's address, not the "
                         f"scheduler's; {form}")
    if found is None:
        what = "no port" if ":" not in (address.partition("://")[2] or address) else \
            "not an address"
        raise BatchError(f"--scheduler {address}: {what}; {form}")
    if scheme is not None and scheme not in DASK_SCHEMES:
        raise BatchError(f"--scheduler {address}: unknown scheme {scheme!r}; {form}")
    if not 1 <= int(found.group("port")) <= 65535:
        raise BatchError(f"--scheduler {address}: port {found.group('port')} is not 1-65535; "
                         f"{form}")
    return address


def connect(address: str, timeout: float = DASK_CONNECT_TIMEOUT_S) -> Any:
    """A ``distributed.Client`` of the Dask scheduler at ``address`` (e.g. tcp://host:8786),
    whose form is checked first (:func:`check_scheduler_address`)."""
    check_scheduler_address(address)
    try:
        from distributed import Client
    except ImportError:
        raise BatchError("a Dask scheduler needs dask.distributed, which is not installed; "
                         "install it with: pip install 'scalematch[dask]'") from None
    try:
        return Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        raise BatchError(f"cannot reach the Dask scheduler at {address}: {exc}") from None


def match_pair_on_worker(pair: Pair, config: Config, max_pixels: int) -> Dict[str, Any]:
    """``match_pair`` as a Dask task: one OpenCV thread per task (the worker threads are the
    parallelism, as the processes of the local pool)."""
    import cv2

    cv2.setNumThreads(1)
    return match_pair(pair, config, max_pixels)


def _dask_threads(client: Any) -> Callable[[], int]:
    """Worker threads of the cluster (at least 1), asked again every DASK_RECHECK_S seconds."""
    state = {"at": -float("inf"), "n": 1}

    def threads() -> int:
        if time.monotonic() - state["at"] > DASK_RECHECK_S:
            state["n"] = max(1, sum(client.nthreads().values()))
            state["at"] = time.monotonic()
        return state["n"]
    return threads


def _dask_wait_first(client: Any, futures: List[Any]) -> Iterable[Any]:
    """The done ones of ``futures`` once at least one is (``distributed.wait`` uses the current
    client: this one, not a default the caller may not have set)."""
    from distributed import wait

    with client.as_current():
        return wait(futures, return_when="FIRST_COMPLETED").done


def run_dask(pairs: Iterable[Pair], config: Config, max_pixels: int,
             client: Any) -> Iterator[Dict[str, Any]]:
    """The lines of ``pairs``, matched on the Dask cluster of ``client``, in the order they finish.

    The workers must have scalematch installed (the same version) and see the image files under
    the paths given (relative paths are resolved on this machine). When the iteration stops early
    the unfinished tasks are cancelled; their pairs get no line, so a resumed batch redoes them.
    """
    threads = _dask_threads(client)
    yield from bounded(
        pairs,
        submit=lambda pair: client.submit(match_pair_on_worker, pair, config, max_pixels,
                                          pure=False),
        wait_first=lambda fs: _dask_wait_first(client, fs),
        outcome=lambda fut, pair: _outcome(fut, pair, config),
        limit=lambda: IN_FLIGHT_PER_WORKER * threads(), stop=client.cancel)
