"""The pairs CSV of a batch: ``read_rows`` (the CSV -> (low, high, other columns) rows, its header
and columns checked: anything that is not a pair of paths is a ``BatchError`` naming the line)
and ``unique_pairs`` (one ``Pair`` per distinct row, relative paths from the CSV's folder).
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Iterable, List, Optional, Sequence, Tuple

from .batch import BatchError, Pair

#: Header names of the two path columns; a column named exactly so wins, else the one column
#: whose name starts with it ("low_path", "high-res", ...). Any other columns are ignored.
COLUMNS = ("low", "high")
#: A first-row cell holding one of these is a path, so the row is data, not a header.
PATH_CHARS = "./\\"


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
