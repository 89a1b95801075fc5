"""Checks of parameter values: one message form, so the library refuses what the command line
refuses and says it the same way (``ValueError``; the CLI prints it as ``Error: ...``, exit 2).

Each ``*Params`` dataclass calls these from its ``__post_init__``: a configuration that cannot
mean anything (a negative RANSAC threshold, a ratio test above 1) is refused when it is made,
not deep inside a match. ``owner`` is the ``Config`` field that holds the parameters
(``"ransac"``; ``""`` for ``Config``'s own fields), so the message names the value as
``--set`` does.

>>> in_range("ransac", "threshold_px", -1.0, lo=0, lo_open=True)
Traceback (most recent call last):
...
ValueError: ransac.threshold_px must be > 0, got -1.0
>>> in_range("matcher", "ratio", 5.0, lo=0, hi=1, lo_open=True)
Traceback (most recent call last):
...
ValueError: matcher.ratio must be in (0, 1], got 5.0
>>> in_range("ransac", "max_iters", 2.5, lo=1, integer=True)
Traceback (most recent call last):
...
ValueError: ransac.max_iters must be an integer >= 1, got 2.5
"""

from __future__ import annotations

import math
from numbers import Integral, Real
from typing import Any, Iterable, Optional


def _path(owner: str, name: str) -> str:
    """The name a user sets a value by: ``ransac.threshold_px`` (``--set``), ``order``."""
    return f"{owner}.{name}" if owner else name


def _rule(lo: Optional[float], hi: Optional[float], lo_open: bool, hi_open: bool) -> str:
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {hi:g}"
    return "a finite number"


def in_range(owner: str, name: str, value: Any, *, lo: Optional[float] = None,
             hi: Optional[float] = None, lo_open: bool = False, hi_open: bool = False,
             integer: bool = False, allow_inf: bool = False) -> None:
    """Raise ``ValueError`` unless ``value`` is a number (an integer with ``integer``) in range.

    NaN is always refused; infinity only passes with ``allow_inf`` (and the bounds).
    """
    rule = _rule(lo, hi, lo_open, hi_open)
    number = isinstance(value, Real) and not isinstance(value, bool)
    ok = number and (isinstance(value, Integral) or not integer)
    if ok:
        v = float(value)
        ok = not math.isnan(v) and (allow_inf or math.isfinite(v))
        ok = ok and (lo is None or (v > lo if lo_open else v >= lo))
        ok = ok and (hi is None or (v < hi if hi_open else v <= hi))
    if not ok:
        kind = "an integer" if integer else "a number"
        must = rule if rule == "a finite number" and not integer else (
            kind if rule == "a finite number" else (f"{kind} {rule}" if integer else rule))
        raise ValueError(f"{_path(owner, name)} must be {must}, got {value!r}")


def one_of(owner: str, name: str, value: Any, choices: Iterable[Any]) -> None:
    """Raise ``ValueError`` unless ``value`` is one of ``choices``.

    >>> one_of("", "order", "sideways", ("auto", "given"))
    Traceback (most recent call last):
    ...
    ValueError: order must be one of ('auto', 'given'), got 'sideways'
    """
    choices = tuple(choices)
    if value not in choices:
        raise ValueError(f"{_path(owner, name)} must be one of {choices}, got {value!r}")
