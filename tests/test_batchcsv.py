"""batchcsv: the pairs CSV read with or without a header (named columns in any position, a
spreadsheet's BOM, blank rows and empty cells), what it cannot read refused naming the line,
repeated rows matched once, relative paths from the CSV's folder."""

from __future__ import annotations

from pathlib import Path

import pytest

from scalematch.batch import BatchError
from scalematch.batchcsv import read_rows, unique_pairs
from test_batch import write


def read_pairs(path: Path):
    """The (low, high) rows of a pairs CSV (``read_rows`` without the other columns)."""
    return [(low, high) for low, high, _ in read_rows(path)]


@pytest.mark.parametrize("text", [
    "a.png,b.png\nc.png,d.png\n",  # no header: two columns, low then high
    "low,high\na.png,b.png\nc.png,d.png\n",
    "\ufeffLOW_PATH , High_Path\na.png,b.png\n\nc.png,d.png\n",  # spreadsheet: BOM, blank row
    "name,high,low,notes\nx,b.png,a.png,n\ny,d.png,c.png,\n",  # named columns, any position
    "low_res,high_res,low\n1,b.png,a.png\n2,d.png,c.png\n",  # the exact name wins
    "a.png,b.png,,\nc.png,d.png\n",  # empty cells at the end of a row are no column
])
def test_read_pairs_columns(tmp_path, text):
    assert read_pairs(write(tmp_path / "p.csv", text)) == [("a.png", "b.png"), ("c.png", "d.png")]


@pytest.mark.parametrize("text,needle", [
    ("name,a.png,b.png\n", "3 columns"),  # no header: a third column is not silently dropped
    ("a.png,b.png\nx.png,y.png,z.png\n", "line 2 has 3 columns"),
    ("only-one-column\n", "has 1 column; without"),
    ("name,low,other\nx,a.png,b.png\n", "no column named 'high'"),
    ("low_a,low_b,high\na.png,b.png,c.png\n", "several columns named 'low'"),
    ("low,high\na.png,\n", "line 2 does not have two paths"),
    ("a,b\nx.png,y.png\n", r"line 1 \(a,b\) reads as a header, but names no columns low"),
])
def test_read_pairs_refuses_what_it_cannot_read(tmp_path, text, needle):
    with pytest.raises(BatchError, match=needle):
        read_pairs(write(tmp_path / "p.csv", text))


def test_unique_pairs_keeps_first_of_repeated_rows_and_resolves_paths(tmp_path):
    rows = [("a.png", "b.png"), ("/abs/c.png", "d.png"), ("a.png", "b.png"), ("b.png", "a.png")]
    pairs = unique_pairs(rows, tmp_path)
    assert [p.key for p in pairs] == [("a.png", "b.png"), ("/abs/c.png", "d.png"),
                                      ("b.png", "a.png")]
    assert pairs[0].low_file == str(tmp_path / "a.png")
    assert pairs[1].low_file == "/abs/c.png" and pairs[1].high_file == str(tmp_path / "d.png")
