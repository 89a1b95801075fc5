"""The command line: a thin click layer over ``read_pair``, ``match`` and ``write_outputs``.

``scalematch LOW HIGH [options]`` runs the ``match`` command (the group routes any first argument
that is not a command name to it); ``scalematch batch pairs.csv`` matches many pairs, one JSON
line each (the work itself is in :mod:`scalematch.batch`). ``bench``, ``repeatability`` and
``covariance`` are registered when their modules are present. Exit codes: ``EXIT_CODES``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import difflib
import importlib
import importlib.machinery
import importlib.util
import math
import os
import re
import sys
import traceback
from pathlib import Path
from typing import (TYPE_CHECKING, Any, Callable, Dict, Iterable, Iterator, List, Optional,
                    Sequence, Tuple)

# The matcher multiplies small matrices (a few hundred descriptors against a few thousand): a
# multi-threaded BLAS spends more time waking threads than computing, 4x slower measured on 2
# busy cores. The command line uses one BLAS thread unless the user says otherwise. BLAS reads
# these when numpy loads, which the imports below do, so they are set here and not in main().
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import click
import numpy as np

from . import __version__
from .errors import internal_error, interrupted
from .config import MAX_SCALES, MAX_SEED, MIN_WORKING_SIDE_PX, MODELS, MODES, ORDERS, Config
from .imageio import DEFAULT_MAX_PIXELS, Decoded, ImageError, decoder_stderr_caught, grey_of_file
from .result import MatchResult, dumps

if TYPE_CHECKING:  # batch imports the pipeline: the command line imports it where used
    from .batch import Counts, Plan

#: Exit codes (the table in --help and README.md). 130 = 128 + SIGINT and 141 = 128 + SIGPIPE,
#: the codes a shell reports for a process those signals end. 4 is not 1: a script must not read
#: a crash (out of memory, a bug) as "no reliable match"; nor 141 a closed pipe.
EXIT_MATCHED, EXIT_NO_MATCH, EXIT_BAD_INPUT, EXIT_PAIR_ERRORS = 0, 1, 2, 3
EXIT_INTERNAL_ERROR = 4
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141
#: What each exit code means, for every command (--help and README.md show this table).
EXIT_CODES = (
    (EXIT_MATCHED, "matched; batch: every pair has its line, none an error"),
    (EXIT_NO_MATCH, "no reliable match"),
    (EXIT_BAD_INPUT, "bad input or usage (image, path, CSV, output file, option value)"),
    (EXIT_PAIR_ERRORS, "batch: some pair has an \"error\" line (this run's or an earlier one's)"),
    (EXIT_INTERNAL_ERROR, "unexpected error (out of memory, a bug), not an answer; -v: traceback"),
    (EXIT_INTERRUPTED, "interrupted (Ctrl-C)"),
    (EXIT_BROKEN_PIPE, "the output pipe was closed by its reader (| head); nothing more written"),
)
#: Exits that skip the interpreter's shutdown (``exit_at_once``): when Ctrl-C stops the main
#: thread, the pipeline's threads (``stages.threads``) may still be inside OpenCV; a thread that
#: comes back from it during the shutdown is ended by the interpreter (pthread_exit), whose
#: unwinding through OpenCV's C++ frames aborts the process (SIGABRT, exit 134: "terminate
#: called without an active exception", "FATAL: exception not rethrown"). After a closed pipe,
#: the shutdown would flush stdout into it again.
EXITS_AT_ONCE = (EXIT_INTERRUPTED, EXIT_BROKEN_PIPE)


#: What --no-views saves on a "no", as measured (docs/design/SPEED.md, 'The time of a "no"':
#: medians, the two searches alternately on one 2-core machine): said in these words in
#: --help, the slow "no"'s hint, README.md and docs/GUIDE.md (tests/test_docs.py)
NO_VIEWS_SPEEDUP = "about 3 times sooner on 1 MP images, 1.5 to 2 times on 12-16 MP photos"

#: Width of an exit-code line in the help (its table is not rewrapped by click): click's
#: 78 columns less the help's indent of 2
EXIT_TEXT_WIDTH = 76
#: What a code means for one command, where the whole table's line is about several.
MATCH_EXIT_TEXT = {EXIT_MATCHED: "matched",
                   EXIT_BAD_INPUT: "bad input or usage (image, path, output file, option value)"}
BATCH_EXIT_TEXT = {
    EXIT_MATCHED: "every pair has its line, none an error (a pair with no reliable match is a "
                  "line too: a batch never exits 1)",
    EXIT_BAD_INPUT: "bad usage (the CSV, an option value, the output file); a pair's missing or "
                    "bad image is its error line (exit 3)",
}


def plural(n: int, word: str) -> str:
    """``word`` as it goes with the count ``n``.

    >>> plural(1, "error"), plural(0, "error"), plural(2, "pair")
    ('error', 'errors', 'pairs')
    """
    return word if n == 1 else word + "s"


def exit_code_table(codes: Iterable[int] = tuple(c for c, _ in EXIT_CODES),
                    texts: Optional[Dict[int, str]] = None) -> str:
    """The exit codes ``codes`` and their meaning, one a line, for a command's help
    (``texts``: the meanings that differ for that command).

    >>> print(exit_code_table((1, 130)))
      1  no reliable match
    130  interrupted (Ctrl-C)
    >>> print(exit_code_table((0,), MATCH_EXIT_TEXT))
      0  matched
    >>> print(exit_code_table((2,), {2: "a meaning " * 9}))  # long ones wrap under themselves
      2  a meaning a meaning a meaning a meaning a meaning a meaning a meaning
         a meaning a meaning
    """
    import textwrap

    wanted, texts = set(codes), texts or {}
    return "\n".join("\n".join(textwrap.wrap(texts.get(code, text), EXIT_TEXT_WIDTH,
                                             initial_indent=f"{code:>3}  ",
                                             subsequent_indent=" " * 5))
                     for code, text in EXIT_CODES if code in wanted)

#: Subcommands that live in other modules: name -> (module, attribute, line of the group's help).
#: Loaded on first use and left out (not listed, "No such command") when the module is absent
#: or cannot be imported; the group's help lists them without importing them.
#: ``lab`` is the lab's group; the other three are short aliases of its commands.
LAZY_COMMANDS = {
    "lab": ("scalematch.lab.cli", "lab", "Research commands: benchmark, studies, covariance."),
    "bench": ("scalematch.lab.bench", "bench_command", "Short for: scalematch lab bench."),
    "repeatability": ("scalematch.lab.repeatability", "repeatability_command",
                      "Short for: scalematch lab repeatability."),
    "covariance": ("scalematch.lab.covariance", "covariance_command",
                   "Short for: scalematch lab covariance."),
}

#: Named threshold options: (option, Config paths, type, help). An option is offered only when
#: its path exists in ``Config()``; any other field can be set with ``--set PATH=VALUE``. A
#: ``{path}`` in a help is that field's default. The values that mean something are checked by
#: the parameters themselves (``scalematch.checks``), so an option, ``--set`` and the library
#: refuse a value with the same message.
THRESHOLD_OPTIONS = (
    ("--harris-threshold", ("harris.threshold", "harris_low.threshold"), click.FLOAT,
     "Cornerness threshold of the scale-adapted Harris detector (both images), "
     "(grey level/px)^4, >= 0."),
    ("--ratio-test", ("matcher.ratio",), click.FLOAT,
     "Nearest / second-nearest descriptor distance ratio to keep a candidate match, in (0, 1]."),
    ("--ransac-threshold", ("ransac.threshold_px",), click.FLOAT,
     "RANSAC inlier distance, low-resolution px, > 0."),
    ("--ransac-iterations", ("ransac.max_iters",), click.INT,
     "RANSAC iterations at most, >= 1."),
    ("--min-inliers", ("decision.min_inliers",), click.INT,
     "Inliers a match needs to count as reliable by their number, >= 0; with fewer, down to "
     "{decision.few_min_inliers}, a match is accepted only when it is far beyond chance and the "
     "pixel check confirms it (--set decision.few_min_inliers=N)."),
    ("--max-log-nfa", ("decision.max_log_nfa",), click.FLOAT,
     "Largest log10 number of false alarms for a match to count as reliable (lower: stricter)."),
)


class InputError(click.ClickException):
    """Bad input (image, path, parameter value): ``Error: ...`` on stderr and exit code 2."""

    exit_code = EXIT_BAD_INPUT


# --------------------------------------------------------------------------- config helpers

def parse_scales(text: str) -> Tuple[float, ...]:
    """"1-8" (unit steps), "2-12:0.5" (steps of 0.5), "1,2,3.5" or a mix ("1-4,6,8") -> scales.

    Raises ``ValueError`` with a message that says the accepted forms, and for more than
    ``MAX_SCALES`` scales before they are listed.

    >>> parse_scales("1-4,6")
    (1.0, 2.0, 3.0, 4.0, 6.0)
    >>> parse_scales("1-16:0.001")
    Traceback (most recent call last):
    ...
    ValueError: scales '1-16:0.001' are 15001 scales, more than the 64 searched at most; take a larger step ("1-16:0.25" is 61)
    >>> parse_scales("1-16:1e-300")
    Traceback (most recent call last):
    ...
    ValueError: scales '1-16:1e-300' are about 1.5e+301 scales, more than the 64 searched at most; take a larger step ("1-16:0.25" is 61)
    """
    out: List[float] = []
    forms = 'use e.g. "1-8", "2-12:0.5" or "1,2,3.5"'
    for item in text.replace(" ", "").split(","):
        if not item:
            continue
        try:
            if "-" in item[1:]:
                out.extend(_scale_range(item, MAX_SCALES - len(out)))
            elif ":" in item:
                raise ValueError
            else:
                out.append(float(item))
        except ValueError as exc:
            if "searched at most" in str(exc):
                raise
            if str(exc).startswith(("scales ", "the step")):
                raise ValueError(f"{exc}; {forms}") from None
            raise ValueError(f"cannot read scales {text!r} at {item!r}; {forms}") from None
    if not out:
        raise ValueError(f"no scales in {text!r}; {forms}")
    return tuple(sorted(set(out)))  # Config checks that each is >= 1


def _has_path(obj: Any, path: str) -> bool:
    for name in path.split("."):
        if not dataclasses.is_dataclass(obj) or name not in {f.name for f in dataclasses.fields(obj)}:
            return False
        obj = getattr(obj, name)
    return True


def _scale_range(item: str, room: int) -> List[float]:
    """The scales of one range "lo-hi" or "lo-hi:step"; ``ValueError`` when it is malformed or
    holds more than ``room`` scales (said before they are listed)."""
    rng, _, step_txt = item.partition(":")
    lo_txt, _, hi_txt = rng.partition("-")
    lo, hi = float(lo_txt), float(hi_txt)
    step = float(step_txt) if step_txt else 1.0
    if not all(math.isfinite(v) for v in (lo, hi, step)):
        raise ValueError(f"scales {item!r} are not finite numbers")
    if hi < lo:
        raise ValueError(f"scales {item!r} go down: write the range from the smaller scale, "
                         f"{hi_txt}-{lo_txt}")
    if not step > 0:
        raise ValueError(f"the step of scales {item!r} must be more than 0")
    span = (hi - lo) / step  # inf where the step is too small for a float to count the steps
    count = math.floor(span + 1e-9) + 1 if math.isfinite(span) else math.inf
    if count > room:
        many = (f"{count} scales" if count < 1e6 else f"about {count:.1e} scales"
                if math.isfinite(count) else "more scales than a float can count")
        raise ValueError(f"scales {item!r} are {many}, more than the {MAX_SCALES} searched "
                         f"at most; take a larger step (\"1-16:0.25\" is 61)")
    n = int(count)
    return [round(lo + k * step, 6) for k in range(n)]


def _coerce(text: str, current: Any, path: str) -> Any:
    """``text`` converted to the type of the field's current value."""
    if path == "scales":  # as --scales writes them: "1-8", "2-12:0.5", "1,2,3.5"
        return parse_scales(text)
    try:
        if isinstance(current, bool):
            low = text.strip().lower()
            if low in ("1", "true", "yes", "on"):
                return True
            if low in ("0", "false", "no", "off"):
                return False
            raise ValueError
        if isinstance(current, int):
            return int(text)
        if isinstance(current, float):
            return float(text)
        if isinstance(current, tuple):
            return _coerce_tuple(text, current)
        if current is None:
            try:
                return float(text) if "." in text or "e" in text.lower() else int(text)
            except ValueError:
                return text
        if isinstance(current, Path):
            return Path(text)
    except ValueError:
        kind = ("groups of numbers split by ';' (e.g. 2;4;6,8)"
                if isinstance(current, tuple) and current and isinstance(current[0], tuple)
                else "comma-separated numbers (e.g. 1,2,4)" if isinstance(current, tuple)
                else f"a {type(current).__name__} value")
        raise ValueError(f"{path} needs {kind}, got {text!r}") from None
    return text


def _coerce_tuple(text: str, current: tuple) -> tuple:
    """Comma-separated numbers; for a tuple of tuples (views.passes), groups split by ";",
    e.g. "2;4;6,8". ``ValueError`` for anything else."""
    if current and isinstance(current[0], tuple):
        return tuple(tuple(float(v) for v in group.split(",") if v.strip())
                     for group in text.split(";") if group.strip())
    return tuple(float(v) for v in text.split(",") if v.strip())


def set_path(config: Any, path: str, value: Any, whole: Optional[str] = None) -> Any:
    """A copy of the (nested, frozen) dataclass ``config`` with ``path`` ("a.b.c") set
    (``whole``: the path as the user wrote it, for the messages; ``path`` by default)."""
    whole = whole or path
    head, _, rest = path.partition(".")
    done = whole[:len(whole) - len(path)]  # the groups already entered, "views." say
    if not dataclasses.is_dataclass(config):
        raise ValueError(f"no parameter {whole!r}: {done.rstrip('.')} is a value, not a group")
    if head not in {f.name for f in dataclasses.fields(config)}:
        names = ", ".join(f.name for f in dataclasses.fields(config))
        raise ValueError(f"no parameter {whole!r} (known here: {names})")
    current = getattr(config, head)
    if rest:
        return dataclasses.replace(config, **{head: set_path(current, rest, value, whole)})
    if dataclasses.is_dataclass(current) and not dataclasses.is_dataclass(value):
        names = ", ".join(f.name for f in dataclasses.fields(current))
        raise ValueError(f"{whole!r} is a group of parameters: set one of them, "
                         f"{whole}.NAME=VALUE (its names: {names})")
    if isinstance(value, str):
        value = _coerce(value, current, whole)
    return dataclasses.replace(config, **{head: value})


@contextlib.contextmanager
def about(option: str) -> Iterator[None]:
    """A ``ValueError`` raised inside names ``option`` first (``--scales 0: scales must be >=
    1, got 0.0``), so that the message says which of the options given was refused."""
    try:
        yield
    except ValueError as exc:
        raise ValueError(f"{option}: {exc}") from None


def build_config(mode: str, model: Optional[str], scales: Optional[str], seed: Optional[int],
                 thresholds: Dict[str, Any], settings: Sequence[str],
                 options: Optional[Dict[str, str]] = None) -> Config:
    """The Config of the command-line options; ``ValueError`` with a message when one is bad,
    naming the option (``options``: the option of each threshold's path, "--ratio-test" say).
    """
    config = Config.preset(mode)  # the modes are presets of the same names
    changes: Dict[str, Any] = {}
    if model is not None:
        changes["model"] = model
    if seed is not None:
        changes["seed"] = seed
    if changes:
        config = dataclasses.replace(config, **changes)
    if scales is not None:
        with about(f"--scales {scales}"):
            config = dataclasses.replace(config, scales=parse_scales(scales))
    for path, value in thresholds.items():
        if value is not None:
            with about(f"{(options or {}).get(path, path)} {value}"):
                config = set_path(config, path, value)
    for item in settings:
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise ValueError(f"--set needs PATH=VALUE (e.g. harris.threshold=50), got {item!r}")
        with about(f"--set {item}"):
            config = set_path(config, key.strip(), value.strip())
    return config


# --------------------------------------------------------------------------- human output

def summary(result: MatchResult) -> str:
    """The one-line verdict on stderr: :func:`render.verdict` (the captions' too) and the time the
    match took (``MatchResult.seconds``: not the reading of the images, nor Python's start)."""
    from .render import verdict

    return f"{verdict(result)}; matching took {result.seconds:.2f} s"  # 0.04 s, not 0.0 s


def scale_table(result: MatchResult) -> str:
    """The per-scale table (the paper's Table 1) as text."""
    head = f"{'s':>7} {'points':>7} {'initial':>7} {'kept':>6} {'inliers':>7} {'outl%':>6} " \
           f"{'ratio':>7} {'rot':>7}"
    from .render import disagreeing_rows

    lines = [head]
    off = set(disagreeing_rows(result))
    for k, r in enumerate(result.scales):
        flag = "  skipped" if r.skipped else ("  <- best" if r.s == result.best_scale else
                                              "  ratio far from s" if k in off else "")
        ratio = f"{r.ratio:7.3f}" if np.isfinite(r.ratio) else f"{'-':>7}"
        rot = f"{r.rotation_deg:7.1f}" if np.isfinite(r.rotation_deg) else f"{'-':>7}"
        lines.append(f"{r.s:7.3g} {r.points:7d} {r.initial:7d} {r.kept:6d} {r.inliers:7d} "
                     f"{r.outlier_pct:6.1f} {ratio} {rot}{flag}")
    return "\n".join(lines)


def _show_progress(quiet: bool) -> bool:
    try:
        return not quiet and sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def _is_terminal(stream: Any) -> bool:
    """Whether ``stream`` writes to a terminal. A batch's lines on a terminal are its progress:
    a bar on stderr beside them would run into them (stdout and stderr share the screen)."""
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


class PlanBar:
    """The progress bar of one match: the units of its search plan done, of all of them (the
    pipeline's ``progress(done, total)``: one unit per scale detected or matched). It appears at
    the pipeline's first report, when the plan's length is known, and keeps that length: the
    bar counts one thing from start to end. It shows no time left: the first units (the
    images themselves, at full size) cost several times the last (small views at coarse
    scales), so a rate-based estimate said 144 s left of a 34 s "no" at 2 % of its units
    (98 s at 5 %, 40 s at 20 %). A context manager: its exit ends the bar's line."""

    def __init__(self, file: Optional[Any] = None) -> None:
        self.file = file
        self.bar: Optional[Any] = None

    def __call__(self, done: int, total: int) -> None:
        if self.bar is None:
            self.bar = click.progressbar(length=max(total, 1), label="matching",
                                         file=self.file or sys.stderr, show_pos=True,
                                         show_eta=False)
            self.bar.__enter__()
        self.bar.update(min(done, self.bar.length) - self.bar.pos)

    def __enter__(self) -> "PlanBar":
        return self

    def __exit__(self, *exc: Any) -> None:
        if self.bar is not None:
            self.bar.__exit__(*exc)


# --------------------------------------------------------------------------- output checks

def _write_probe(folder: Path) -> None:
    """Create and remove a file in ``folder`` (raises ``OSError`` when none can be written);
    nothing is left, and no name the run writes appears and vanishes."""
    import tempfile  # imported where used: the command line starts faster

    with tempfile.NamedTemporaryFile(dir=folder, prefix=".scalematch-check-"):
        pass


def check_out_dir(path: Path) -> None:
    """Create ``path`` and make sure a file can be written in it, before the work starts."""
    try:
        path.mkdir(parents=True, exist_ok=True)
        _write_probe(path)
    except OSError as exc:
        raise InputError(f"cannot write to the output directory {path}: "
                         f"{exc.strerror or exc}; choose another with --out-dir")


def check_out_file(path: Path, option: str) -> None:
    """Make sure ``path`` can be written before the work: its folder is created when missing (as
    ``--out-dir`` is), and the file can be opened for appending."""
    if path.is_dir():
        raise InputError(f"{option} {path} is a directory; give a file name")
    parent = path.parent if str(path.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot write {option} {path}: cannot create the folder {parent}: "
                         f"{exc.strerror or exc}")
    try:
        if path.exists():
            with open(path, "a"):
                pass
        else:  # a file beside it, not the file itself: nothing appears at ``path`` and vanishes
            _write_probe(parent)
    except OSError as exc:
        raise InputError(f"cannot write {option} {path}: {exc.strerror or exc}")


def _file_id(path: Any) -> Any:
    """What identifies the file ``path`` names: (device, inode) when it exists (so a hard link or
    another spelling is the same file), else its absolute path with links resolved."""
    try:
        st = os.stat(path)
        return (st.st_dev, st.st_ino)
    except (OSError, ValueError):
        return os.path.realpath(path)


def check_not_an_input(path: Path, inputs: Iterable[Any], option: str,
                       instead: str = "file") -> None:
    """Refuse (exit 2) to write ``path`` when it is one of ``inputs`` under any name: an output
    never overwrites an input (``--json v.png``, ``-o DIR`` holding an input named overlay.png,
    ``batch --output`` naming the CSV or an image)."""
    target = _file_id(path)
    for source in inputs:
        if _file_id(source) == target:
            same = "" if str(source) == str(path) else f" (the same file as {source})"
            raise InputError(f"{option} {path} is an input{same}: it would be overwritten; "
                             f"choose another {instead}")


def write_text(path: Path, text: str, option: str) -> None:
    try:
        path.write_text(text)
    except OSError as exc:
        raise InputError(f"cannot write {option} {path}: {exc.strerror or exc}")


# --------------------------------------------------------------------------- the group

class ScalematchGroup(click.Group):
    """A group whose default command is ``match``, with lazily imported extra commands."""

    default_command = "match"

    def main(self, args: Optional[Sequence[str]] = None, prog_name: Optional[str] = None,
             complete_var: Optional[str] = None, standalone_mode: bool = True,
             **extra: Any) -> Any:
        """Click's main, with every error on one line (a usage error says where help is, in
        place of click's usage block: 4 lines), Ctrl-C exiting 130 and a closed output pipe
        141, neither 1 (no match)."""
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)
        try:
            rv = super().main(args, prog_name, complete_var, False, **extra)
        except click.UsageError as exc:
            hint = f" Try '{exc.ctx.command_path} --help' for help." if exc.ctx else ""
            click.echo(f"Error: {exc.format_message()}{hint}", err=True)
            sys.exit(exc.exit_code)
        except click.ClickException as exc:
            exc.show()
            sys.exit(exc.exit_code)
        except (click.Abort, KeyboardInterrupt):
            # Ctrl-C: click turns KeyboardInterrupt into Abort, and passes on one that comes
            # while it ends
            click.echo("interrupted", err=True)
            sys.exit(EXIT_INTERRUPTED)
        except Exception as exc:  # noqa: BLE001 (anything else is ours: exit 4, never 1)
            if interrupted(exc):  # Ctrl-C, worn by a library's error raised as it unwound
                click.echo("interrupted", err=True)
                sys.exit(EXIT_INTERRUPTED)
            given = sys.argv[1:] if args is None else list(args)
            if "-v" in given or "--verbose" in given:
                traceback.print_exc(file=sys.stderr)
                hint = ""
            else:
                hint = " (-v shows the traceback)"
            click.echo(f"Error: {internal_error(exc)}{hint}", err=True)
            sys.exit(EXIT_INTERNAL_ERROR)
        sys.exit(rv if isinstance(rv, int) else 0)

    def make_context(self, *args: Any, **kwargs: Any) -> click.Context:
        with closed_pipe_ends_quietly():  # the group's --help and --version write here
            return super().make_context(*args, **kwargs)

    def invoke(self, ctx: click.Context) -> Any:
        with closed_pipe_ends_quietly():  # the commands, their --help
            return super().invoke(ctx)

    def _known(self) -> set:
        return set(self.commands) | set(LAZY_COMMANDS)

    def parse_args(self, ctx: click.Context, args: List[str]) -> List[str]:
        if not args and not ctx.resilient_parsing:
            # nothing to do: the help with its examples, on stderr, as a usage error (exit 2)
            # without "Error:" (click's own would be "Error: Usage: ...")
            click.echo(ctx.get_help(), err=True)
            ctx.exit(EXIT_BAD_INPUT)
        own = {"--help", "-h", "--version"}
        if args and args[0] not in self._known() and args[0] not in own:
            near = mistyped_command(args[0], self._known())
            if near:
                raise click.UsageError(f"no command or file {args[0]!r}; did you mean "
                                       f"'{near}'?", ctx)
            args = [self.default_command] + list(args)
        return super().parse_args(ctx, args)

    def get_command(self, ctx: click.Context, name: str) -> Optional[click.Command]:
        cmd = super().get_command(ctx, name)
        if cmd is not None or name not in LAZY_COMMANDS:
            return cmd
        module, attr, _ = LAZY_COMMANDS[name]
        try:
            return getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError):
            return None

    def list_commands(self, ctx: click.Context) -> List[str]:
        return list(self.commands) + [n for n, (module, _, _) in LAZY_COMMANDS.items()
                                      if _module_exists(module)]

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        # the lazy commands are found, not imported: the help does not load the lab
        limit = formatter.width - 6 - max(len(n) for n in self._known())
        rows = [(n, LAZY_COMMANDS[n][2] if n in LAZY_COMMANDS
                 else self.commands[n].get_short_help_str(limit))
                for n in self.list_commands(ctx)
                if n in LAZY_COMMANDS or not self.commands[n].hidden]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@contextlib.contextmanager
def closed_pipe_ends_quietly() -> Iterator[None]:
    """Exit 141 (128 + SIGPIPE, as a writer killed by its closed pipe), with nothing more
    written, when stdout or stderr is a pipe whose reader has gone (``| head -1`` once head has
    its line): click would exit 1, which means "no reliable match". A ``BrokenPipeError`` that
    gets here is the output's: the batch's pipes to its workers handle their own."""
    try:
        yield
    except BrokenPipeError:
        sys.exit(EXIT_BROKEN_PIPE)


def mistyped_command(word: str, commands: Sequence[str]) -> Optional[str]:
    """The command ``word`` looks like a typo of, when it is no file and no path either
    (``scalematch mtch a b`` would otherwise say "File 'mtch' does not exist").

    >>> mistyped_command("mtch", ["match", "batch", "lab"]), mistyped_command("low.png", ["match"])
    ('match', None)
    """
    if word.startswith("-") or os.path.exists(word) or any(c in word for c in "./\\"):
        return None
    near = difflib.get_close_matches(word, sorted(commands), n=1, cutoff=0.6)
    return near[0] if near else None


def _module_exists(name: str) -> bool:
    """Whether module ``name`` ("scalematch.lab.cli") can be found, without running its package."""
    package, _, _ = name.rpartition(".")
    try:
        spec = importlib.util.find_spec(package)  # imports only the packages above ``package``
    except ImportError:
        return False
    places = spec.submodule_search_locations if spec is not None else None
    return bool(places) and importlib.machinery.PathFinder.find_spec(name, places) is not None


CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 100}


def exit_codes_in_help(*codes: int,
                       texts: Optional[Dict[int, str]] = None) -> Callable[[Callable], Callable]:
    """A decorator putting the table of ``codes`` (all when none; ``texts``: the command's own
    meanings) in place of the line ``{exit_codes}`` of a command's docstring (put it under
    the click decorators)."""
    def decorate(f: Callable) -> Callable:
        lines = []
        for line in (f.__doc__ or "").split("\n"):
            if line.strip() == "{exit_codes}":
                indent = line[:len(line) - len(line.lstrip())]
                table = exit_code_table(codes or tuple(c for c, _ in EXIT_CODES), texts)
                lines += [indent + row for row in table.split("\n")]
            else:
                lines.append(line)
        f.__doc__ = "\n".join(lines).replace("{no_views_speedup}", NO_VIEWS_SPEEDUP)
        return f
    return decorate


@click.group(cls=ScalematchGroup, context_settings=CONTEXT)
@click.version_option(__version__, "--version", prog_name="scalematch",
                      message="%(prog)s %(version)s")
@exit_codes_in_help()
def cli() -> None:
    """Match a low-resolution image against a high-resolution image of the same scene with
    unknown zoom (2x-16x) and rotation (Dufournaud, Schmid & Horaud, CVIU 2004).

    Without a command name, the arguments go to the match command. Each command's
    options: scalematch match --help, scalematch batch --help.

    \b
    Examples:
      scalematch low.jpg high.jpg
      scalematch low.jpg high.jpg -o out/ --json out/result.json
      scalematch low.png high.png --model homography --scales 1-8 --json -
      scalematch batch pairs.csv --output results.jsonl --jobs 4

    \b
    Exit codes:
    {exit_codes}
    """


def matching_options(f: Callable) -> Callable:
    """The options shared by ``match`` and ``batch``: what is matched and how."""
    for opt in reversed(_search_options() + _threshold_options() + _value_options()):
        f = opt(f)
    return f


def _search_options() -> List[Callable]:
    """The options of the search: the model, the mode, the order, views, time, no-data, size."""
    return [
        click.option("--model", type=click.Choice(MODELS), default=None,
                     help="Transform fitted from high-res px to low-res px: homography for a "
                          "planar scene seen from another viewpoint or in perspective (Oxford "
                          "graf, a facade from below). [default: similarity]"),
        click.option("--mode", type=click.Choice(MODES), default="default", show_default=True,
                     help="'paper': the method as published (jets, Mahalanobis, semi-local "
                          "constraints, scales 1-8)."),
        click.option("--order", type=click.Choice(ORDERS), default="auto", show_default=True,
                     help="'auto': find which image is the finer one (the given order is tried "
                          "first, then the other; the JSON says which). 'given': LOW is the "
                          "coarser image."),
        click.option("--views/--no-views", "views", default=True, show_default=True,
                     help="When nothing matches, simulate tilted views of both images "
                          "(oblique shots; the coarser one's views solve a finer image seen "
                          "more obliquely than its zoom): tilts 2, then 4, then 6 and 8, each "
                          "pass one vote over all their pairs, and only when the earlier passes "
                          "found nothing. They are most of the time of a \"no\": with "
                          f"--no-views a \"no\" comes {NO_VIEWS_SPEEDUP} "
                          "(docs/design/SPEED.md; for archives of mostly unrelated pairs), but "
                          "pairs only a tilted view solves are missed; --set "
                          "\"views.passes=2;4\" leaves out the steepest pass (1.6x sooner)."),
        click.option("--time-budget", type=float, default=None, metavar="SECONDS",
                     help="Start no further step of the search after SECONDS (the given "
                          "order's plain search always runs): a pair with no match is answered "
                          "sooner, but one only the other order or a tilted view would solve is "
                          "missed, and the answer then depends on the machine's speed. "
                          "[default: no limit]"),
        click.option("--nodata", default=None, metavar="auto|none|VALUE",
                     help="Where an image shows no scene: 'auto' finds a canvas left by a "
                          "rotation or a warp (a region of one grey level at the border, "
                          "bounded by the picture's straight, slanted edges); VALUE declares a "
                          "grey level that is no-data wherever it covers a region (as GDAL "
                          "rasters declare theirs; 0-255 as the image's 8-bit levels); 'none': "
                          "every pixel is scene. No-data keeps no points and is left out of "
                          "the pixel tests; a clipped sky or a backdrop is scene. The JSON's "
                          "low.nodata and high.nodata say what was taken. [default: auto]"),
        click.option("--working-size", type=click.INT, default=None, metavar="PX",
                     help="Match an image whose longer side exceeds PX at that size and give "
                          f"the answer in its own pixels: 0 (always full size) or at least "
                          f"{MIN_WORKING_SIDE_PX}; the high image only with --order auto. "
                          "[default: 2048]"),
        click.option("--scales", metavar="LIST",
                     help='Scales s of the high-res image to try: "1-8", "2-12:0.5" or '
                          '"1,2,3.5". [default: 1-16 in third octaves; paper mode 1-8]'),
    ]


def _threshold_options() -> List[Callable]:
    """The decision's thresholds as options (``THRESHOLD_OPTIONS``), their defaults shown."""
    base, opts = Config(), []
    for name, paths, typ, text in THRESHOLD_OPTIONS:
        paths = [p for p in paths if _has_path(base, p)]
        if paths:
            dest = "thr_" + name[2:].replace("-", "_")
            opts.append(click.option(name, dest, type=typ, default=None,
                                     help=f"{_with_defaults(text, base)} (Config "
                                          f"{', '.join(paths)}) [default: {_get(base, paths[0])}]"))
    return opts


def _value_options() -> List[Callable]:
    """Any parameter by its path, the seed, and the largest image read."""
    return [
        click.option("--set", "settings", multiple=True, metavar="PATH=VALUE",
                     help="Set any Config field, e.g. --set harris.sigma_tilde=2.5 (repeatable)."),
        click.option("--seed", type=click.IntRange(0, MAX_SEED), default=None,
                     help="Seed of all randomness (RANSAC); same input, same output. "
                          "[default: 0]"),
        click.option("--max-pixels", type=click.IntRange(min=1), default=DEFAULT_MAX_PIXELS,
                     show_default=True,
                     help="Refuse images with more pixels than this, from their header, before "
                          "decoding them (OpenCV itself decodes at most 1073741824)."),
    ]


def _get(obj: Any, path: str) -> Any:
    for name in path.split("."):
        obj = getattr(obj, name)
    return obj


def _with_defaults(text: str, config: Any) -> str:
    """``text`` with each ``{path}`` of a field of ``config`` replaced by its value.

    >>> _with_defaults("down to {decision.few_min_inliers} inliers", Config())
    'down to 4 inliers'
    """
    return re.sub(r"\{([a-z_.]+)\}", lambda m: str(_get(config, m.group(1)))
                  if _has_path(config, m.group(1)) else m.group(0), text)


def _config_from(kwargs: Dict[str, Any]) -> Config:
    base = Config()
    thresholds, options = {}, {}
    for name, paths, _, _ in THRESHOLD_OPTIONS:
        value = kwargs.pop("thr_" + name[2:].replace("-", "_"), None)
        for p in paths:
            if _has_path(base, p):
                thresholds[p], options[p] = value, name
    try:
        config = build_config(kwargs.pop("mode"), kwargs.pop("model"), kwargs.pop("scales"),
                              kwargs.pop("seed"), thresholds,
                              tuple(kwargs.pop("settings"))
                              + (f"order={kwargs.pop('order')}",
                                 f"views.enabled={kwargs.pop('views')}"), options)
        budget = kwargs.pop("time_budget")
        if budget is not None and math.isinf(budget) and budget > 0:
            budget = None  # inf: no limit, as without the option
        if budget is not None:
            if not budget > 0:
                raise ValueError(f"--time-budget must be more than 0 seconds, got {budget:g}")
            config = set_path(config, "time_budget_s", float(budget))
        nodata = kwargs.pop("nodata")
        if nodata is not None:
            from .stages.nodata import parse_rule

            config = set_path(config, "nodata.rule", parse_rule(nodata))
        working = kwargs.pop("working_size")
        if working is not None and (working < 0 or 0 < working < MIN_WORKING_SIDE_PX):
            raise ValueError(f"--working-size must be 0 (always full size) or at least "
                             f"{MIN_WORKING_SIDE_PX} px, got {working}")
        if working is not None:  # 0: always full size
            config = dataclasses.replace(config, low_max_side=working or None,
                                         high_max_side=working or None)
    except ValueError as exc:
        raise InputError(str(exc))
    return config


def _load(low: str, high: str, config: Config, max_pixels: int) -> Tuple[Decoded, Decoded]:
    from .working import read_pair  # a JPEG far above its working size: decoded at 1/2 ... 1/8

    try:
        return read_pair(low, high, config, max_pixels)
    except ImageError as exc:
        raise InputError(str(exc))


def _run_match(low: np.ndarray, high: np.ndarray, config: Config,
               progress: Optional[Callable[[int, int], None]] = None,
               factors: Tuple[float, float] = (1.0, 1.0)) -> MatchResult:
    from .pipeline import match  # imported here so the CLI starts (and --help works) fast

    return match(low, high, config, progress=progress, decoded_factors=factors)


# --------------------------------------------------------------------------- match

@cli.command("match", context_settings=CONTEXT)
@click.argument("low", type=click.Path())
@click.argument("high", type=click.Path())
@click.option("-o", "--out-dir", type=click.Path(file_okay=False, path_type=Path),
              help="Write overlay.png, matches.png, scales.png and matches.csv here.")
@click.option("--json", "json_path", metavar="PATH",
              help="Write the result as JSON here ('-' for stdout; a missing folder is created, "
                   "as for --out-dir); written whether or not a match was found, and for an "
                   "image that cannot be read or matched (exit 2) with its \"error\".")
@matching_options
@click.option("-q", "--quiet", is_flag=True, help="No summary and no progress bar on stderr.")
@click.option("-v", "--verbose", is_flag=True,
              help="Also print the per-scale table, the timings and the files written (and the "
                   "traceback of an unexpected error).")
@exit_codes_in_help(EXIT_MATCHED, EXIT_NO_MATCH, EXIT_BAD_INPUT, EXIT_INTERNAL_ERROR,
                    EXIT_INTERRUPTED, EXIT_BROKEN_PIPE, texts=MATCH_EXIT_TEXT)
def match_command(low: str, high: str, out_dir: Optional[Path], json_path: Optional[str],
                  quiet: bool, verbose: bool, max_pixels: int, **kwargs: Any) -> None:
    """Match LOW (low-resolution image) against HIGH (high-resolution image).

    Finds the zoom ratio (2x-16x), rotation and translation taking HIGH's pixels to LOW's, or
    says "no reliable match". A one-line summary goes to stderr: the verdict and the time the
    matching took (not the reading of the images, nor Python's start).

    \b
    Examples:
      scalematch low.jpg high.jpg
      scalematch low.jpg high.jpg -o out/ --json out/result.json
      scalematch low.png high.png --mode paper --scales 1-8 --json - -q
      scalematch low.png high.png --ransac-threshold 2 --set harris.threshold=50

    \b
    Exit codes:
    {exit_codes}
    """
    click.get_current_context().with_resource(decoder_stderr_caught())  # stderr is ours
    if quiet and verbose:
        raise click.UsageError("-q (--quiet) and -v (--verbose) exclude each other; give one.")
    config = _config_from(kwargs)
    json_file = Path(json_path) if json_path and json_path != "-" else None
    # the outputs are checked before the match, not after a minute's work, and before the
    # inputs are read: an output never overwrites an input
    _check_not_inputs(out_dir, json_file, (low, high))
    with _json_of_error(json_path, json_file, low, high, config):
        low_read, high_read = _load(low, high, config, max_pixels)
        grey = _greys(low, high, low_read, high_read)  # a constant image: named, nothing made
    factors = (float(low_read.factor), float(high_read.factor))
    with _removed_if_empty(_check_writable(out_dir, json_file)), \
            _json_of_error(json_path, json_file, low, high, config):
        result = _match_images(*grey, config, factors, quiet)
        if json_path:  # only when asked: every inlier is written (0.1 s for 1,700 of them)
            _write_json(result.to_json(low, high, low_read.shape, high_read.shape,
                                       warnings=(low_read.warning, high_read.warning)),
                        json_file)
    written: Dict[str, Path] = {}
    if out_dir is not None:
        written = _write_pictures(out_dir, low, high, low_read.image, high_read.image, result,
                                  factors)
    if not quiet:
        json_written = json_path if json_file is not None else None
        for text in _match_report(result, written, json_written, verbose,
                                  (low_read.shape, high_read.shape),
                                  (low_read.warning, high_read.warning)):
            click.echo(text, err=True)
    sys.exit(EXIT_MATCHED if result.matched else EXIT_NO_MATCH)


@contextlib.contextmanager
def _json_of_error(json_path: Optional[str], json_file: Optional[Path], low: str,
                   high: str, config: Config) -> Iterator[None]:
    """With ``--json``, the record of an error raised inside (``result.error_record``, as a
    batch writes it), so that a script reading the JSON learns why rather than finding nothing:
    kind "input" for a bad input (exit 2), "internal" for an unexpected error (exit 4: out of
    memory, a bug). The error goes on, and nothing more is written when the JSON cannot be
    written either. Ctrl-C writes nothing: it is not an answer about the pair."""
    try:
        yield
    except InputError as exc:
        _write_error_json(json_path, json_file, low, high, config, exc.format_message(), "input")
        raise
    except (click.ClickException, click.Abort):
        raise
    except Exception as exc:  # noqa: BLE001 (recorded, then passed on: exit 4 in main)
        if not interrupted(exc):
            _write_error_json(json_path, json_file, low, high, config, internal_error(exc),
                              "internal")
        raise


def _write_error_json(json_path: Optional[str], json_file: Optional[Path], low: str, high: str,
                      config: Config, message: str, kind: str) -> None:
    """The error record of ``--json`` where it can still be written (best effort: the error
    that brought it here matters more than one that writing it meets)."""
    if not json_path:
        return
    try:
        from .result import dumps, error_record

        text = dumps(error_record(low, high, message, kind, config), 2)
        if json_file is not None:
            check_out_file(json_file, "--json")
        _write_json(text + "\n", json_file)
    except Exception:  # noqa: BLE001 (a full disk, memory gone: the first error is the one said)
        pass


def _check_not_inputs(out_dir: Optional[Path], json_file: Optional[Path],
                      inputs: Sequence[str]) -> None:
    """Refuse (exit 2) an output file of ``-o`` or ``--json`` that is one of ``inputs`` or
    one of the other's files, and ``-o -`` (standard output is for ``--json -`` only: the
    pictures are files)."""
    from .render import OUTPUT_FILES

    if out_dir is not None and str(out_dir) == "-":
        raise InputError("--out-dir - : the pictures and matches.csv are files, not a stream; "
                         "give a folder (--json - writes the JSON to standard output)")
    if out_dir is not None:
        for name in OUTPUT_FILES:
            check_not_an_input(out_dir / name, inputs, "--out-dir", "folder")
    if json_file is not None:
        check_not_an_input(json_file, inputs, "--json")
    if out_dir is not None and json_file is not None:
        for name in OUTPUT_FILES:
            if _file_id(out_dir / name) == _file_id(json_file):
                raise InputError(f"--json {json_file} is {name}, which --out-dir {out_dir} "
                                 f"writes: one would overwrite the other; name the JSON "
                                 f"otherwise (result.json, say)")


def _check_writable(out_dir: Optional[Path], json_file: Optional[Path]) -> List[Path]:
    """Create the folders of ``-o`` and ``--json`` and make sure they can be written (exit 2);
    the folders of ``-o`` that this created, deepest first."""
    made = []
    if out_dir is not None:
        missing = out_dir.absolute()
        while not missing.exists():
            made.append(missing)
            missing = missing.parent
        check_out_dir(out_dir)
    if json_file is not None:
        check_out_file(json_file, "--json")
    return made


@contextlib.contextmanager
def _removed_if_empty(folders: Sequence[Path]) -> Iterator[None]:
    """Remove ``folders`` (deepest first) again when the block inside fails and they are still
    empty: a match refused (exit 2) or failed leaves no empty ``-o`` folder behind."""
    try:
        yield
    except BaseException:
        for folder in folders:
            try:
                folder.rmdir()  # only an empty folder
            except OSError:
                break
        raise


def _greys(low: str, high: str, low_read: Decoded, high_read: Decoded
           ) -> Tuple[np.ndarray, np.ndarray]:
    """The grey levels of the two images read; exit 2 naming the file of one that leaves
    nothing to match (constant)."""
    try:
        return grey_of_file(low_read.image, low), grey_of_file(high_read.image, high)
    except ImageError as exc:
        raise InputError(str(exc))


def _match_images(low: np.ndarray, high: np.ndarray, config: Config,
                  factors: Tuple[float, float], quiet: bool) -> MatchResult:
    """The match of the grey images, with a progress bar unless ``quiet`` (or not a terminal);
    an input the pipeline refuses, or a file the configuration names that is missing, is exit
    2."""
    try:
        if _show_progress(quiet):
            with PlanBar() as bar:
                return _run_match(low, high, config, bar, factors)
        return _run_match(low, high, config, factors=factors)
    except ImageError as exc:
        raise InputError(str(exc))
    except ValueError as exc:  # the pipeline refuses the input (e.g. an image too small)
        raise InputError(str(exc))
    except OSError as exc:  # a file the configuration names is missing (e.g. --set ..._path=)
        raise InputError(str(exc))


def _write_json(text: str, json_file: Optional[Path]) -> None:
    """The result's JSON to ``json_file``, or to stdout when None (``--json -``); exit 2 when
    it cannot be written (a full disk), as for a file (a closed pipe: ``closed_pipe_ends_quietly``).
    """
    if json_file is None:
        try:
            click.echo(text, nl=False)
        except BrokenPipeError:
            raise
        except OSError as exc:
            raise InputError(f"cannot write --json to stdout: {exc.strerror or exc}")
    else:
        write_text(json_file, text, "--json")


def _write_pictures(out_dir: Path, low: str, high: str, low_img: np.ndarray, high_img: np.ndarray,
                    result: MatchResult, factors: Tuple[float, float]) -> Dict[str, Path]:
    """The files of ``-o`` (``render.write_outputs``), by name; exit 2 when they cannot be
    written."""
    from .render import write_outputs

    try:
        return write_outputs(out_dir, low, high, low_img, high_img, result, factors)
    except OSError as exc:
        raise InputError(f"cannot write the outputs to {out_dir}: {exc}")


def _match_report(result: MatchResult, written: Dict[str, Path], json_written: Optional[str],
                  verbose: bool, shapes: Optional[Tuple[Sequence[int], Sequence[int]]] = None,
                  warnings: Sequence[str] = ()) -> List[str]:
    """What the match says on stderr: first, a ``Warning:`` line for each of ``warnings`` (what
    the reading of an image warned of: ``Decoded.warning``, a damaged file decoded anyway,
    said once, here rather than before the match, so that a run ending in an error says only
    its ``Error:`` line); the verdict line (``summary``), after the per-scale table,
    the timings and the files written (``written`` by ``-o``, ``json_written`` by ``--json``: its
    path as given) when ``verbose``; without ``verbose``, where the files went, in one line.
    A slow "no" of a search with views says how to get a quicker one (:func:`slow_no_hint`); a
    "no" between images of ``shapes`` too different in size for the ratios searched says how to
    search larger ones (:func:`larger_ratio_hint`), one in the given order only whose first
    image is the larger, how to try the other (:func:`order_hint`). The verdict comes last."""
    hints = [slow_no_hint(result)] + ([larger_ratio_hint(result, *shapes),
                                        order_hint(result, *shapes)] if shapes else [])
    lines = [f"Warning: {text}" for text in warnings if text] + [hint for hint in hints if hint]
    if verbose:
        lines.append(scale_table(result))
        lines.append("timings: " + ", ".join(f"{k} {v:.2f} s" for k, v in result.timings.items()))
        lines += [f"wrote {path}" for path in written.values()]
        if json_written is not None:
            lines.append(f"wrote {json_written}")
        return lines + [summary(result)]
    where = ([f"{', '.join(p.name for p in written.values())} in "
              f"{next(iter(written.values())).parent}"] if written else []) + \
        ([str(json_written)] if json_written is not None else [])
    return lines + (["wrote " + "; ".join(where)] if where else []) + [summary(result)]


#: A "no" slower than this, s, with views searched, says where the time went (its views) and
#: what answers sooner; a "no" on unrelated 12 and 16 MP photos takes a median 6.0 s (at most
#: 6.2) as a whole process on a 2-core machine, more when other jobs share it
#: (docs/design/SPEED.md), on 1 MP images a median of 2 to 4 s
SLOW_NO_HINT_S = 10.0


def slow_no_hint(result: MatchResult) -> str:
    """The hint a slow "no" prints, or "" (a match, a quick "no", a search without views)."""
    views = any(step.view_pass > 0 for step in result.search)
    if result.matched or not views or result.seconds < SLOW_NO_HINT_S:
        return ""
    return (f"most of this \"no\" was spent on tilted views: with --no-views a \"no\" comes "
            f"{NO_VIEWS_SPEEDUP}, and only pairs that a tilted view alone solves are missed "
            f"(--time-budget S bounds it instead)")


def larger_ratio_hint(result: MatchResult, low_shape: Sequence[int],
                      high_shape: Sequence[int]) -> str:
    """The hint a "no" prints when one image is more times the other's size (longer sides)
    than the largest ratio searched, or "". A finer image whose footprint lies inside the
    coarser one has a ratio of at least their size ratio, so the ratios searched could not
    hold the answer; ``--scales`` from that size ratio to four times it searches them.

    >>> from scalematch.result import ScaleRow
    >>> rows = tuple(ScaleRow(s, s, 10, 0, 0, 0, 100.0) for s in (1.0, 4.0, 16.0))
    >>> larger_ratio_hint(MatchResult(False, "similarity", scales=rows), (56, 100), (1400, 1800))
    'the high image is 18 times the low one in size, and ratios up to 16 were searched: if it lies inside the low image, its ratio is at least 18 (--scales 18-72 searches 18 to 72)'
    >>> larger_ratio_hint(MatchResult(False, "similarity", scales=rows), (480, 640), (480, 640))
    ''
    """
    if result.matched or not result.scales:
        return ""
    top = max(row.s for row in result.scales)
    low_side, high_side = max(low_shape[:2]), max(high_shape[:2])
    size = max(low_side, high_side) / max(min(low_side, high_side), 1)
    if size <= top:
        return ""
    larger = "high" if high_side >= low_side else "low"
    smaller = "low" if larger == "high" else "high"
    lo = int(math.floor(size))
    return (f"the {larger} image is {size:.0f} times the {smaller} one in size, and ratios up "
            f"to {top:g} were searched: if it lies inside the {smaller} image, its ratio is at "
            f"least {lo} (--scales {lo}-{4 * lo} searches {lo} to {4 * lo})")


def order_hint(result: MatchResult, low_shape: Sequence[int], high_shape: Sequence[int]) -> str:
    """The hint a "no" searched in the given order only (``--order given``) prints when its
    first image (LOW, taken as the coarser one) is the larger, or "": the images may be the
    other way round.

    >>> from scalematch.config import Config
    >>> given = MatchResult(False, "similarity", config=Config(order="given"))
    >>> order_hint(given, (1536, 2048), (512, 683))[:60]
    'only the given order was searched (--order given), and LOW i'
    >>> order_hint(given, (512, 683), (1536, 2048)), order_hint(
    ...     MatchResult(False, "similarity", config=Config()), (1536, 2048), (512, 683))
    ('', '')
    """
    if result.matched or result.config is None or result.config.order != "given" or \
            max(low_shape[:2]) <= max(high_shape[:2]):
        return ""
    return ("only the given order was searched (--order given), and LOW is the larger image: if "
            "LOW is the finer one, --order auto (the default) tries both")


# --------------------------------------------------------------------------- batch

def _batch_lines(pairs: List[Any], config: Config, max_pixels: int, jobs: int,
                 client: Any) -> Iterator[Dict[str, Any]]:
    """The result lines of ``pairs`` from the runner the options ask for."""
    from . import batch

    if client is not None:
        return batch.run_dask(pairs, config, max_pixels, client)
    if jobs == 1 or len(pairs) <= 1:  # decoded here: stderr is ours, the decoders' words caught
        click.get_current_context().with_resource(decoder_stderr_caught())
        return batch.run_serial(pairs, config, max_pixels)
    return batch.run_pool(pairs, config, max_pixels, jobs)


@cli.command("batch", context_settings=CONTEXT)
@click.argument("pairs_csv", metavar="PAIRS.csv",
                type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Append JSON lines here instead of stdout (a missing folder is created); "
                   "resumable: the pairs already in it are skipped. It must be new or the output "
                   "of an earlier batch run with the same options (anything else is refused, "
                   "exit 2).")
@click.option("--retry-errors", is_flag=True,
              help="When resuming, match again the pairs whose line in --output is an error "
                   "(the file is rewritten without those lines first; every other line kept).")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=1, show_default=True,
              help="Worker processes on this machine.")
@click.option("--scheduler", metavar="ADDRESS",
              help="Run on the Dask cluster of this scheduler (e.g. tcp://host:8786) instead of "
                   "local processes; needs pip install 'scalematch[dask]'.")
@matching_options
@click.option("-q", "--quiet", is_flag=True, help="No progress bar and no summary on stderr.")
@click.option("-v", "--verbose", is_flag=True,
              help="The traceback of an unexpected error of the batch itself (a pair's is in its "
                   "line).")
@exit_codes_in_help(EXIT_MATCHED, EXIT_BAD_INPUT, EXIT_PAIR_ERRORS, EXIT_INTERNAL_ERROR,
                    EXIT_INTERRUPTED, EXIT_BROKEN_PIPE, texts=BATCH_EXIT_TEXT)
def batch_command(pairs_csv: Path, output: Optional[Path], retry_errors: bool, jobs: int,
                  scheduler: Optional[str], quiet: bool, **kwargs: Any) -> None:
    """Match every pair of PAIRS.csv, one JSON line per pair.

    PAIRS.csv has two columns low,high (no header), or a header row naming the columns low and
    high (or low_path,high_path, ...) in any position among others. Relative paths are taken
    from the CSV's folder, and each line gives the paths as the CSV writes them; with a header,
    the row's other columns come back on its line as "csv" (name: text), an id or the ratio
    expected, say. A repeated row is matched once. Each line is the JSON of
    "scalematch LOW HIGH --json" (without indentation), written and flushed as soon as the pair
    is done, in the order pairs finish. Its "low" and "high" are the coarser and the finer image
    as found: with "order": "swapped", "low" is the file of the CSV's high column. A pair that
    cannot be matched (missing file, bad image) gets a line with "error" and the batch goes on;
    its "error_kind" is "input" (the pair's files or values) or "internal" (out of memory, a
    bug). A worker killed by the system (out of memory) is started again and its pair tried
    again alone; a pair whose worker died twice gets an internal error line. --jobs beyond the
    machine's cores runs one worker a core.

    Resuming: with --output, running the same command again after an interruption (Ctrl-C,
    kill, power cut) skips the pairs already in the file (delete a line to redo its pair), error
    lines included; with --retry-errors the pairs of the CSV whose line is an error are matched
    again (a fixed image, more memory), their error lines removed first. The options must be
    the same: a file holding results made with other options is refused (exit 2), never mixed
    (so each example below writes its own file; the third resumes the second's).

    An archive of mostly unrelated pairs: with --no-views a "no" comes {no_views_speedup}
    (docs/design/SPEED.md), but oblique pairs only a tilted view solves are missed.

    \b
    Examples:
      scalematch batch pairs.csv > results.jsonl
      scalematch batch pairs.csv --output paper.jsonl --jobs 2 --mode paper
      scalematch batch pairs.csv --output paper.jsonl --jobs 2 --mode paper --retry-errors
      scalematch batch archive.csv --output archive.jsonl --no-views
      scalematch batch pairs.csv --output cluster.jsonl --scheduler tcp://host:8786

    \b
    Exit codes (4 before 3 when a pair of this run had an internal error):
    {exit_codes}
    """
    jobs_given = click.get_current_context().get_parameter_source("jobs")
    if scheduler is not None and jobs_given != click.core.ParameterSource.DEFAULT:
        raise click.UsageError("--jobs is for local processes; with --scheduler the Dask "
                               "workers' threads set the parallelism.")
    if retry_errors and output is None:
        raise click.UsageError("--retry-errors matches again the pairs whose line in the output "
                               "file is an error; give that file with --output.")
    max_pixels, _ = kwargs.pop("max_pixels"), kwargs.pop("verbose")  # -v: the group reads it
    config = _config_from(kwargs)
    plan, client = _batch_plan(pairs_csv, output, retry_errors, scheduler, config)
    for note in () if quiet else _batch_notes(plan, pairs_csv, output):
        click.echo(note, err=True)
    jobs = _local_workers(jobs, quiet or client is not None)
    counts = _write_batch(plan, _batch_lines(list(plan.todo), config, max_pixels, jobs, client),
                          output, quiet, client)
    if not quiet:
        click.echo(_batch_summary(plan, counts), err=True)
    code = _batch_exit_code(plan, counts)
    if code != EXIT_MATCHED:
        sys.exit(code)


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity, where the system tells it)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except (AttributeError, OSError):
        return max(os.cpu_count() or 1, 1)


def workers_for(jobs: int, cores: int) -> Tuple[int, str]:
    """(worker processes, what to say of it): at most one per core. Each match already keeps
    a core busy, so more workers than cores only share them, each holding its images in
    memory (--jobs 64 on 2 cores: about 30 workers, 4.1 GB, and slower, 14.1 s against 9.8 s
    for 30 pairs).

    >>> workers_for(64, 2)
    (2, '--jobs 64: this machine has 2 cores, so 2 worker processes run')
    >>> workers_for(2, 8)
    (2, '')
    """
    if jobs <= cores:
        return jobs, ""
    return cores, (f"--jobs {jobs}: this machine has {cores} {plural(cores, 'core')}, so {cores} worker "
                   f"{'process runs' if cores == 1 else 'processes run'}")


def _local_workers(jobs: int, quiet: bool) -> int:
    """The worker processes of ``--jobs``, at most one a core (:func:`workers_for`), said once
    on stderr when fewer than asked (unless ``quiet``)."""
    jobs, note = workers_for(jobs, available_cores())
    if note and not quiet:
        click.echo(note, err=True)
    return jobs


def _batch_plan(pairs_csv: Path, output: Optional[Path], retry_errors: bool,
                scheduler: Optional[str], config: Config) -> Tuple[Plan, Any]:
    """The run's ``batch.Plan`` and its Dask client (None: local processes). What refuses the
    run is exit 2: the scheduler's address, the CSV, the output file (an input, not writable,
    not a batch output of these options). The output file is changed (``batch.resume_output``)
    only once nothing else can refuse the run."""
    from . import batch

    recorded = batch.config_json(config)
    done, retried, client = batch.NOTHING_DONE, frozenset(), None
    try:
        if scheduler is not None:  # its form first: a malformed address fails at once
            batch.check_scheduler_address(scheduler)
        rows = batch.read_rows(pairs_csv)
        pairs = batch.unique_pairs(rows, pairs_csv.resolve().parent)
        if output is not None:
            check_not_an_input(output, [pairs_csv] + [f for p in pairs
                                                      for f in (p.low_file, p.high_file)],
                               "--output")
            check_out_file(output, "--output")
            done = batch.scan_output(output, recorded)
        client = batch.connect(scheduler) if scheduler is not None else None
        if output is not None:
            retry = batch.errors_to_retry(done, pairs) if retry_errors else frozenset()
            done, retried = batch.resume_output(output, done, retry, recorded)
    except batch.BatchError as exc:
        if client is not None:
            client.close()
        raise InputError(str(exc))
    return batch.plan_run(len(rows), pairs, done, retried), client


def _batch_notes(plan: Plan, pairs_csv: Path, output: Optional[Path]) -> List[str]:
    """What the run says on stderr before it starts: repeated rows, pairs skipped, retried."""
    notes = []
    if not plan.pairs:
        notes.append(f"{pairs_csv} lists no pairs")
    if plan.repeated_rows:
        notes.append(f"rows repeated in {pairs_csv}: {plan.repeated_rows} (each pair is "
                     f"matched once)")
    if plan.skipped:
        notes.append(f"resuming: {plan.skipped} of {len(plan.pairs)} pairs already in {output}")
    if plan.retried:
        n = len(plan.retried)
        notes.append(f"retrying {n} pair{'' if n == 1 else 's'} whose line was an error (removed "
                     f"from {output})")
    return notes


def _write_batch(plan: Plan, lines: Iterator[Dict[str, Any]], output: Optional[Path],
                 quiet: bool, client: Any) -> Counts:
    """Write each of ``lines`` to ``output`` (appended; stdout when None) as it comes, with a
    progress bar unless ``quiet`` (or the lines go to a terminal: they show the progress); the ``batch.Counts`` of the lines. Ctrl-C exits 130 with how
    many pairs were done. The workers, the file and the Dask ``client`` are closed at the end,
    however it comes."""
    from . import batch

    counts = batch.Counts()
    out_fh = open(output, "a") if output is not None else sys.stdout
    bar = click.progressbar(length=len(plan.todo), label="matching pairs", file=sys.stderr,
                            show_pos=True) if _show_progress(quiet) and not (
        output is None and _is_terminal(sys.stdout)) else None
    try:
        if bar is not None:
            bar.__enter__()
        for line in lines:
            out_fh.write(dumps(line) + "\n")
            out_fh.flush()
            counts = counts.add(line)
            if bar is not None:
                bar.update(1)
    except KeyboardInterrupt:
        hint = "; run the same command again to resume" if output is not None else ""
        click.echo(f"\ninterrupted: {counts.lines} of {len(plan.todo)} pairs done{hint}",
                   err=True)
        sys.exit(EXIT_INTERRUPTED)
    finally:
        lines.close()  # stops the workers now if the loop ended early
        if bar is not None:
            bar.__exit__(None, None, None)
        if output is not None:
            out_fh.close()
        if client is not None:
            client.close()
    return counts


def _batch_summary(plan: Plan, counts: Counts) -> str:
    """The run's last line on stderr: the pairs of this run by verdict, and those done before."""
    before = (f" ({plan.skipped} done before, {plan.errors_before} of them "
              f"{'an error' if plan.errors_before == 1 else 'errors'})" if plan.skipped else "")
    n = len(plan.todo)
    return (f"{n} {plural(n, 'pair')}: {counts.matched} matched, {counts.no_match} no reliable "
            f"match, {counts.errors} {plural(counts.errors, 'error')}"
            f"{f' ({counts.internal} internal)' if counts.internal else ''}{before}")


def _batch_exit_code(plan: Plan, counts: Counts) -> int:
    """4 when a pair of this run had an internal error, else 3 when any pair's line is an error
    (this run's or an earlier one's), else 0."""
    if counts.internal:
        return EXIT_INTERNAL_ERROR
    if counts.errors or plan.errors_before:
        return EXIT_PAIR_ERRORS
    return EXIT_MATCHED


# --------------------------------------------------------------------------- help

@cli.command("help", context_settings=CONTEXT)
@click.argument("command", required=False)
def help_command(command: Optional[str]) -> None:
    """Show the help of scalematch or of one command.

    \b
    Examples:
      scalematch help
      scalematch help batch
    """
    ctx = click.get_current_context()
    group_ctx = ctx.parent
    if command is None:
        click.echo(group_ctx.get_help())
        return
    cmd = group_ctx.command.get_command(group_ctx, command)
    if cmd is None:
        raise click.UsageError(f"no command {command!r}; the commands: "
                               f"{', '.join(group_ctx.command.list_commands(group_ctx))}.")
    with click.Context(cmd, info_name=command, parent=group_ctx) as sub:
        click.echo(cmd.get_help(sub))


def main(argv: Optional[Sequence[str]] = None) -> None:
    """Console entry point (``scalematch``): ends at once with the codes of ``EXITS_AT_ONCE``."""
    try:
        cli.main(args=list(argv) if argv is not None else None, prog_name="scalematch")
    except SystemExit as exc:
        if exc.code in EXITS_AT_ONCE:
            exit_at_once(exc.code)
        raise


def exit_at_once(code: int) -> None:
    """End the process with ``code`` once stdout and stderr are flushed (as far as they can
    be), without the interpreter's shutdown (``EXITS_AT_ONCE`` says why). Whatever the command
    holds is closed by then: the batch closes its output file and stops its workers and its
    Dask client before it exits."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):  # a closed pipe, a closed file
            pass
    os._exit(code)


if __name__ == "__main__":
    main()
