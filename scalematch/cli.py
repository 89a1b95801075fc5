"""The command line: a thin click layer over ``read_pair``, ``match`` and ``write_outputs``.

``scalematch LOW HIGH [options]`` runs the ``match`` command (the group routes any first argument
that is not a command name to it); ``scalematch batch pairs.csv`` matches many pairs, one JSON
line each (the work itself is in :mod:`scalematch.batch`). ``bench``, ``repeatability`` and
``covariance`` are registered when their modules are present. Exit codes: ``EXIT_CODES``.

What the commands do around the library is in the modules named by their job: the options and
the ``Config`` they give (:mod:`scalematch.options`), the files written and checked
(:mod:`scalematch.outputs`), what stderr says (:mod:`scalematch.report`), a batch's run
(:mod:`scalematch.batchrun`) and the exit codes (:mod:`scalematch.exits`).
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.machinery
import importlib.util
import os
import sys
from pathlib import Path
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence, Tuple

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
from .batchrun import (batch_exit_code, batch_lines, batch_notes, batch_plan, batch_summary,
                       local_workers, write_batch)
from .config import Config
from .errors import internal_error, interrupted
from .exits import (BATCH_EXIT_TEXT, EXIT_BAD_INPUT, EXIT_BROKEN_PIPE, EXIT_CODES,
                    EXIT_INTERNAL_ERROR, EXIT_INTERRUPTED, EXIT_MATCHED, EXIT_NO_MATCH,
                    EXIT_PAIR_ERRORS, EXITS_AT_ONCE, MATCH_EXIT_TEXT, InputError, exit_at_once,
                    exit_code_table)
from .greylevels import grey_of_file
from .imagefile import ImageError
from .imageio import Decoded, decoder_stderr_caught
from .options import NO_VIEWS_SPEEDUP, config_from, matching_options
# re-exported: lab/regress.py (--tree) imports scalematch.cli.set_path, where older trees have it
from .options import set_path as set_path
from .outputs import (check_not_inputs, check_writable, json_of_error, removed_if_empty,
                      write_json, write_pictures)
from .report import PlanBar, match_report, show_progress
from .result import MatchResult


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
                import traceback

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
    import difflib

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
    config = config_from(kwargs)
    json_file = Path(json_path) if json_path and json_path != "-" else None
    # the outputs are checked before the match, not after a minute's work, and before the
    # inputs are read: an output never overwrites an input
    check_not_inputs(out_dir, json_file, (low, high))
    with json_of_error(json_path, json_file, low, high, config):
        low_read, high_read = _load(low, high, config, max_pixels)
        grey = _greys(low, high, low_read, high_read)  # a constant image: named, nothing made
    factors = (float(low_read.factor), float(high_read.factor))
    with removed_if_empty(check_writable(out_dir, json_file)), \
            json_of_error(json_path, json_file, low, high, config):
        result = _match_images(*grey, config, factors, quiet)
        if json_path:  # only when asked: every inlier is written (0.1 s for 1,700 of them)
            write_json(result.to_json(low, high, low_read.shape, high_read.shape,
                                      warnings=(low_read.warning, high_read.warning)),
                       json_file)
    written: Dict[str, Path] = {}
    if out_dir is not None:
        written = write_pictures(out_dir, low, high, low_read.image, high_read.image, result,
                                 factors)
    if not quiet:
        json_written = json_path if json_file is not None else None
        for text in match_report(result, written, json_written, verbose,
                                 (low_read.shape, high_read.shape),
                                 (low_read.warning, high_read.warning)):
            click.echo(text, err=True)
    sys.exit(EXIT_MATCHED if result.matched else EXIT_NO_MATCH)


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
        if show_progress(quiet):
            with PlanBar() as bar:
                return _run_match(low, high, config, bar, factors)
        return _run_match(low, high, config, factors=factors)
    except ImageError as exc:
        raise InputError(str(exc))
    except ValueError as exc:  # the pipeline refuses the input (e.g. an image too small)
        raise InputError(str(exc))
    except OSError as exc:  # a file the configuration names is missing (e.g. --set ..._path=)
        raise InputError(str(exc))


# --------------------------------------------------------------------------- batch

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
    _check_batch_usage(scheduler, retry_errors, output)
    max_pixels, _ = kwargs.pop("max_pixels"), kwargs.pop("verbose")  # -v: the group reads it
    config = config_from(kwargs)
    plan, client = batch_plan(pairs_csv, output, retry_errors, scheduler, config)
    for note in () if quiet else batch_notes(plan, pairs_csv, output):
        click.echo(note, err=True)
    jobs = local_workers(jobs, quiet or client is not None)
    counts = write_batch(plan, batch_lines(list(plan.todo), config, max_pixels, jobs, client),
                         output, quiet, client)
    if not quiet:
        click.echo(batch_summary(plan, counts), err=True)
    code = batch_exit_code(plan, counts)
    if code != EXIT_MATCHED:
        sys.exit(code)


def _check_batch_usage(scheduler: Optional[str], retry_errors: bool,
                       output: Optional[Path]) -> None:
    """Refuse (exit 2) the options of ``batch`` that exclude or need each other."""
    jobs_given = click.get_current_context().get_parameter_source("jobs")
    if scheduler is not None and jobs_given != click.core.ParameterSource.DEFAULT:
        raise click.UsageError("--jobs is for local processes; with --scheduler the Dask "
                               "workers' threads set the parallelism.")
    if retry_errors and output is None:
        raise click.UsageError("--retry-errors matches again the pairs whose line in the output "
                               "file is an error; give that file with --output.")


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


if __name__ == "__main__":
    main()
