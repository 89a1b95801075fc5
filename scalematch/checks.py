"""Checks of parameter values: one message form, so the library refuses what the command line
refuses and says it the same way (``ValueError``; the CLI prints it as ``Error: ...``, exit 2).

Each ``*Params`` dataclass declares the range of each of its numbers once, in a class-level
table (``BOUNDS``: field name -> :class:`Bounds`), which its ``__post_init__`` checks with
:func:`check_bounds`: a configuration that cannot mean anything (a negative RANSAC threshold, a
ratio test above 1) is refused when it is made, not deep inside a match. ``owner`` is the ``Config`` field that holds the parameters
(``"ransac"``; ``""`` for ``Config``'s own fields), so the message names the value as
``--set`` does.

>>> in_range("ransac", "threshold_px", -1.0, Bounds(lo=0, lo_open=True))
Traceback (most recent call last):
...
ValueError: ransac.threshold_px must be > 0, got -1.0
>>> in_range("matcher", "ratio", 5.0, Bounds(lo=0, hi=1, lo_open=True))
Traceback (most recent call last):
...
ValueError: matcher.ratio must be in (0, 1], got 5.0
>>> in_range("ransac", "max_iters", 2.5, Bounds(lo=1), integer=True)
Traceback (most recent call last):
...
ValueError: ransac.max_iters must be an integer >= 1, got 2.5
>>> in_range("harris", "threshold", float("inf"), Bounds(lo=0))
Traceback (most recent call last):
...
ValueError: harris.threshold must be finite and >= 0, got inf
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any, Iterable, Mapping, Optional


def _path(owner: str, name: str) -> str:
    """The name a user sets a value by: ``ransac.threshold_px`` (``--set``), ``order``."""
    return f"{owner}.{name}" if owner else name


@dataclass(frozen=True)
class Bounds:
    """The range a value must lie in: from ``lo`` to ``hi`` (None: unbounded on that side),
    each end included unless ``lo_open`` / ``hi_open``.

    >>> Bounds(lo=0, hi=1, lo_open=True).rule(), Bounds(lo=1).rule(), Bounds().rule()
    ('in (0, 1]', '>= 1', 'a finite number')
    >>> Bounds(lo=0, hi=2**31 - 1).rule()  # whole numbers in full
    'in [0, 2147483647]'
    """

    lo: Optional[float] = None
    hi: Optional[float] = None
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False  #: whole numbers only
    allow_inf: bool = False  #: infinity passes (within the range)
    optional: bool = False  #: None passes (the field's "not set")

    def rule(self) -> str:
        """The range in words, as the error message says it."""
        lo, hi = _number(self.lo), _number(self.hi)
        if lo and hi:
            return (f"in {'(' if self.lo_open else '['}{lo}, {hi}"
                    f"{')' if self.hi_open else ']'}")
        if lo:
            return f"{'>' if self.lo_open else '>='} {lo}"
        if hi:
            return f"{'<' if self.hi_open else '<='} {hi}"
        return "a finite number"

    def holds(self, v: float) -> bool:
        """Whether the number ``v`` lies in the range."""
        return ((self.lo is None or (v > self.lo if self.lo_open else v >= self.lo))
                and (self.hi is None or (v < self.hi if self.hi_open else v <= self.hi)))


def _number(v: Optional[float]) -> str:
    """``v`` as a message writes it: a whole number in full, others as ``:g`` does; "" for
    None."""
    if v is None:
        return ""
    return str(int(v)) if float(v).is_integer() else f"{v:g}"


def in_range(owner: str, name: str, value: Any, bounds: Bounds = Bounds(), *,
             integer: bool = False, allow_inf: bool = False) -> None:
    """Raise ``ValueError`` unless ``value`` is a number (an integer with ``integer`` or
    ``bounds.integer``) within ``bounds``.

    NaN is always refused; infinity only passes with ``allow_inf`` or ``bounds.allow_inf``
    (and the range).
    """
    integer = integer or bounds.integer
    allow_inf = allow_inf or bounds.allow_inf
    rule = bounds.rule()
    number = isinstance(value, Real) and not isinstance(value, bool)
    ok = number and (isinstance(value, Integral) or not integer)
    if ok:
        v = float(value)
        ok = not math.isnan(v) and (allow_inf or math.isfinite(v))
        ok = ok and bounds.holds(v)
    if not ok:
        kind = "an integer" if integer else "a number"
        must = rule if rule == "a finite number" and not integer else (
            kind if rule == "a finite number" else (f"{kind} {rule}" if integer else rule))
        if number and not integer and math.isinf(float(value)) and not allow_inf \
                and rule != "a finite number":
            must = f"finite and {must}"  # ">= 0, got inf" read as a contradiction
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


#: The ranges most parameters take, by what they are.
POSITIVE = Bounds(lo=0, lo_open=True)  #: a length, a std, a factor that must not vanish
NON_NEGATIVE = Bounds(lo=0)
#: The largest count: OpenCV takes its counts (RANSAC iterations, points) as C ints
MAX_COUNT = 2**31 - 1
COUNT = Bounds(lo=0, hi=MAX_COUNT, integer=True)  #: how many (0: none, or off where it says so)
AT_LEAST_ONE = Bounds(lo=1, hi=MAX_COUNT, integer=True)
SHARE = Bounds(lo=0, hi=1)  #: a fraction
PROBABILITY = Bounds(lo=0, hi=1, lo_open=True, hi_open=True)  #: a RANSAC confidence
FACTOR = Bounds(lo=1)  #: a ratio between two sizes, >= 1
CORRELATION = Bounds(lo=-1, hi=1)  #: a ZNCC
MARGIN = Bounds(lo=-2, hi=2)  #: a difference of two correlations
ANGLE = Bounds(lo=0, hi=180)  #: a tolerance on an angle, degrees
FINITE = Bounds()  #: any finite number (a log10 NFA)


def check_bounds(owner: str, params: Any, table: Mapping[str, Bounds]) -> None:
    """Check each field of ``params`` that ``table`` names against its :class:`Bounds`: the
    one place a ``*Params`` declares its ranges (``BOUNDS``, a class-level table).

    >>> from dataclasses import dataclass
    >>> @dataclass(frozen=True)
    ... class P:
    ...     radius: float = 2.0
    ...     rounds: int = 3
    >>> check_bounds("p", P(rounds=0), {"radius": POSITIVE, "rounds": AT_LEAST_ONE})
    Traceback (most recent call last):
    ...
    ValueError: p.rounds must be an integer in [1, 2147483647], got 0
    """
    for name, bounds in table.items():
        value = getattr(params, name)
        if value is None and bounds.optional:
            continue
        in_range(owner, name, value, bounds)

