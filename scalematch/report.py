"""What the command line says to a person on stderr: the verdict line, the per-scale table,
the hints of a "no" (a quicker one, larger ratios, the other order), the progress bars."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import click
import numpy as np

from .options import NO_VIEWS_SPEEDUP
from .result import MatchResult


def plural(n: int, word: str) -> str:
    """``word`` as it goes with the count ``n``.

    >>> plural(1, "error"), plural(0, "error"), plural(2, "pair")
    ('error', 'errors', 'pairs')
    """
    return word if n == 1 else word + "s"


def summary(result: MatchResult) -> str:
    """The one-line verdict on stderr: :func:`verdict.verdict` (the captions' too) and the time the
    match took (``MatchResult.seconds``: not the reading of the images, nor Python's start)."""
    from .verdict import verdict

    return f"{verdict(result)}; matching took {result.seconds:.2f} s"  # 0.04 s, not 0.0 s


def scale_table(result: MatchResult) -> str:
    """The per-scale table (the paper's Table 1) as text."""
    head = f"{'s':>7} {'points':>7} {'initial':>7} {'kept':>6} {'inliers':>7} {'outl%':>6} " \
           f"{'ratio':>7} {'rot':>7}"
    from .scalechart import disagreeing_rows

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


def show_progress(quiet: bool) -> bool:
    try:
        return not quiet and sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def is_terminal(stream: Any) -> bool:
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


def match_report(result: MatchResult, written: Dict[str, Path], json_written: Optional[str],
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
