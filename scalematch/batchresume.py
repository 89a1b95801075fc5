"""A batch's output file read back and resumed: ``scan_output`` (what an earlier run left in the
output file: the pairs done and which of them errored; it refuses a file holding anything but
result lines, or results made with another configuration, said as the options that differ:
``options_of``), ``drop_error_lines`` (with ``--retry-errors``: the error lines of pairs to match
again removed, the file replaced in one step; ``resume_output`` does this or cuts a torn last
line) and ``plan_run`` (the ``Plan``: the pairs to match, those skipped, those retried).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import (Any, Collection, Dict, FrozenSet, Iterable, Iterator, List, Optional, Sequence,
                    Tuple)

from .batch import BatchError, Pair
from .config import Config
from .result import dumps, to_jsonable

#: The start of every line ``dumps`` writes: a last line torn by an interruption starts so too.
LINE_START = b'{"'


@dataclass(frozen=True)
class Done:
    """What an earlier run left in the output file."""

    pairs: FrozenSet[Tuple[str, str]]  #: (low, high) of every complete result line
    errors: FrozenSet[Tuple[str, str]]  #: those whose line holds an "error"
    complete_bytes: int  #: length of the complete lines; anything after it was torn


NOTHING_DONE = Done(frozenset(), frozenset(), 0)


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
