"""The command line's exit codes and what each means (the table of every command's --help and
README.md), the error of a bad input (exit 2), and the exit that skips the interpreter's shutdown.
"""

from __future__ import annotations

import os
import sys
from typing import Dict, Iterable, Optional

import click


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


class InputError(click.ClickException):
    """Bad input (image, path, parameter value): ``Error: ...`` on stderr and exit code 2."""

    exit_code = EXIT_BAD_INPUT


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
