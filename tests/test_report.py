"""report: what the command line says on stderr: the progress bar, the per-scale table, the hints
of a "no"."""

from __future__ import annotations

import io
import json
import re

import cv2
import numpy as np

from scalematch.report import (SLOW_NO_HINT_S, PlanBar, match_report, scale_table,
                               slow_no_hint)
from test_cli import DEMO_HIGH, DEMO_LOW, needs_pipeline, run
from test_scalechart import collapsed_fit_result


class _Terminal(io.StringIO):
    """A stream that click takes for a terminal: its progress bar is drawn there."""

    def isatty(self) -> bool:
        return True


@needs_pipeline
def test_the_progress_bar_counts_the_plan_from_start_to_end():
    """Every state the bar shows has the same total, the plan's; the count only grows, and ends
    at the total (the search stops early on the demo pair: the rest is counted as done)."""
    from scalematch.cli import _run_match
    from scalematch.config import Config
    from scalematch.imageio import read_grey

    screen = _Terminal()
    with PlanBar(screen) as bar:
        _run_match(read_grey(DEMO_LOW), read_grey(DEMO_HIGH), Config(), bar)
    shown = [(int(done), int(total)) for done, total
             in re.findall(r"matching.*?(\d+)/(\d+)", screen.getvalue())]
    assert len(shown) >= 2, screen.getvalue()
    assert len({total for _, total in shown}) == 1, shown
    done = [d for d, _ in shown]
    assert done == sorted(done) and done[-1] == shown[-1][1]


def test_the_progress_bar_shows_no_time_left():
    """Its units differ several times in cost, so a rate-based time left misleads."""
    with PlanBar(_Terminal()) as bar:
        bar(1, 100)
        assert bar.bar is not None and bar.bar.show_eta is False


def test_a_slow_no_with_views_says_how_to_get_a_quicker_one():
    from dataclasses import replace

    from scalematch.result import Direction, MatchResult, StepRecord

    plain = StepRecord(Direction.GIVEN, 0, 1, 1, 3.0, False)
    views = replace(plain, view_pass=1, views=5)
    slow = MatchResult(matched=False, model="similarity", reason="too few inliers",
                       timings={"total": SLOW_NO_HINT_S + 20}, search=(plain, views))
    assert "--no-views" in slow_no_hint(slow)
    assert match_report(slow, {}, None, False)[0] == slow_no_hint(slow)  # before the verdict
    assert slow_no_hint(replace(slow, timings={"total": SLOW_NO_HINT_S / 4})) == ""
    assert slow_no_hint(replace(slow, search=(plain,))) == ""  # no views: nothing to drop
    assert slow_no_hint(replace(slow, matched=True, reason="")) == ""


def test_a_no_beyond_the_ratios_searched_says_which_scales_would_search_it(raccoon, tmp_path):
    """A 41x pair (the whole photo 100 px wide against a detail 1,800 px wide) is a "no" over
    the default ratios, 1 to 16; the hint names a --scales range that holds the ratio, and that
    range matches it (within 2 %)."""
    width = raccoon.shape[1]
    low = cv2.resize(raccoon, (100, round(100 * raccoon.shape[0] / width)),
                     interpolation=cv2.INTER_AREA)
    high = cv2.resize(raccoon[200:650, 300:750], (1800, 1800), interpolation=cv2.INTER_CUBIC)
    ratio = 4.0 * width / 100
    cv2.imwrite(str(tmp_path / "low.png"), np.clip(low, 0, 255).astype(np.uint8))
    cv2.imwrite(str(tmp_path / "high.png"), np.clip(high, 0, 255).astype(np.uint8))
    no = run(tmp_path / "low.png", tmp_path / "high.png", "--no-views")
    assert no.exit_code == 1, no.output
    hint = re.search(r"--scales (\d+)-(\d+) searches", no.stderr)
    assert hint and "the high image is 18 times the low one" in no.stderr, no.stderr
    lo, hi = int(hint.group(1)), int(hint.group(2))
    assert lo <= ratio <= hi
    yes = run(tmp_path / "low.png", tmp_path / "high.png", "--scales", f"{lo}-{hi}", "--json",
              "-", "-q")
    assert yes.exit_code == 0, yes.output
    assert abs(json.loads(yes.stdout)["resolution_ratio"] / ratio - 1) < 0.02


def test_the_verbose_table_says_which_rows_are_not_counted():
    lines = scale_table(collapsed_fit_result()).splitlines()[1:]
    assert lines[0].endswith("ratio far from s") and lines[3].endswith("ratio far from s")
    assert lines[1].endswith("<- best") and "far" not in lines[2]
