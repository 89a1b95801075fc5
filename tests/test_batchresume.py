"""batchresume: the output file (refused when it holds anything but results, or results of other
options, said as the options that differ; a torn line cut; error lines removed to retry their
pairs, the file replaced in one step) and the plan of a run (the pairs done skipped, those to
retry)."""

from __future__ import annotations

import json
import os
import stat

import pytest

from scalematch.batch import BatchError, Pair
from scalematch.batchresume import (NOTHING_DONE, Done, config_json, cut_torn_line,
                                    drop_error_lines, errors_to_retry, plan_run, resume_output,
                                    scan_output)
from scalematch.config import Config
from test_batch import write


# --------------------------------------------------------------------------- the output file

def _line(low: str, high: str, config=None, error: bool = False) -> str:
    obj = {"low": {"path": low}, "high": {"path": high}, "matched": not error,
           "config": config_json(Config()) if config is None else config}
    if error:
        obj["error"] = "no such file"
    return json.dumps(obj) + "\n"


def test_scan_output_counts_results_and_their_errors(tmp_path):
    assert scan_output(tmp_path / "new.jsonl", config_json(Config())) == NOTHING_DONE
    out = write(tmp_path / "r.jsonl", _line("a", "b") + "\n" + _line("c", "d", error=True))
    done = scan_output(out, config_json(Config()))
    assert done.pairs == {("a", "b"), ("c", "d")} and done.errors == {("c", "d")}
    assert done.complete_bytes == out.stat().st_size


def test_a_swapped_line_is_the_pair_as_given(tmp_path):
    # the CSV row fine.png,coarse.png gave the finer image first: its line names the images as
    # found (low: the coarser), with order "swapped"
    swapped = json.loads(_line("coarse.png", "fine.png"))
    swapped["order"] = "swapped"
    out = write(tmp_path / "r.jsonl", json.dumps(swapped) + "\n")
    assert scan_output(out, config_json(Config())).pairs == {("fine.png", "coarse.png")}


def test_a_torn_last_line_is_not_counted_and_is_cut(tmp_path):
    good = _line("a", "b")
    out = write(tmp_path / "r.jsonl", good + _line("c", "d")[:30])
    done = scan_output(out, config_json(Config()))
    assert done.pairs == {("a", "b")} and done.complete_bytes == len(good)
    cut_torn_line(out, done)
    assert out.read_text() == good


@pytest.mark.parametrize("text", [
    "my notes\n",
    "my notes without a newline at the end",
    "low,high\na.png,b.png\n",  # the pairs CSV itself
    '{"a": 1}\n',  # JSON, but not a result line
    '{"low": {"path": "a"}, "high": {"path": "b"}, "matched": true}\n'
    "a note after a result\n",
])
def test_scan_output_refuses_a_file_with_other_lines(tmp_path, text):
    out = write(tmp_path / "notes.txt", text)
    with pytest.raises(BatchError, match="not a scalematch result"):
        scan_output(out, config_json(Config()))


def test_scan_output_refuses_results_of_other_options(tmp_path):
    other = config_json(Config(model="homography"))
    out = write(tmp_path / "r.jsonl", _line("a", "b", config=other))
    with pytest.raises(BatchError, match="made with --model homography; this run: no matching"):
        scan_output(out, config_json(Config()))


def test_options_of_says_a_configuration_as_the_options_that_give_it():
    from scalematch.batchresume import OPTION_OF_PATH, options_of
    from scalematch.options import THRESHOLD_OPTIONS, build_config

    def typed(mode="default", model=None, scales=None, seed=None, *settings):
        return config_json(build_config(mode, model, scales, seed, {}, settings))

    assert options_of(typed("paper", None, None, None, "views.enabled=True")) == ["--mode paper"]
    assert options_of(typed("default", "affine", "1-8", 3, "views.enabled=False",
                            "ransac.threshold_px=2", "guided.radius_px=5")) == [
        "--set guided.radius_px=5.0", "--model affine", "--ransac-threshold 2.0",
        "--scales 1,2,3,4,5,6,7,8", "--seed 3", "--no-views"]
    for _, paths, _, _ in THRESHOLD_OPTIONS:  # every threshold option is said as typed
        assert all(p in OPTION_OF_PATH for p in paths), paths


def test_drop_error_lines_removes_only_those_asked_and_keeps_every_other_byte(tmp_path):
    good, blank = _line("a", "b"), "\n"
    kept_error = _line("e", "f", error=True)  # not asked: kept
    both_error, both_good = _line("g", "h", error=True), _line("g", "h")  # a pair with two lines
    real = write(tmp_path / "real.jsonl", good + blank + _line("c", "d", error=True) + kept_error
                 + both_error + both_good + _line("x", "y")[:30])  # ... and a torn last line
    os.chmod(real, 0o640)
    out = tmp_path / "r.jsonl"
    out.symlink_to(real)
    done = drop_error_lines(out, {("c", "d"), ("g", "h")}, config_json(Config()))
    assert real.read_text() == good + blank + kept_error + both_good
    assert done == scan_output(out, config_json(Config()))
    assert done.pairs == {("a", "b"), ("e", "f"), ("g", "h")} and done.errors == {("e", "f")}
    assert out.is_symlink() and stat.S_IMODE(real.stat().st_mode) == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.jsonl", "real.jsonl"]  # no temp file


def test_drop_error_lines_refuses_a_file_with_other_lines_and_leaves_it(tmp_path):
    text = _line("c", "d", error=True) + "my notes\n"
    out = write(tmp_path / "r.jsonl", text)
    with pytest.raises(BatchError, match="line 2 is not a scalematch result"):
        drop_error_lines(out, {("c", "d")}, config_json(Config()))
    assert out.read_text() == text and [p.name for p in tmp_path.iterdir()] == ["r.jsonl"]


# --------------------------------------------------------------------------- what a run does

def _pairs(*names):
    return [Pair(n, n + "'", n, n + "'") for n in names]


def test_plan_run_of_a_new_output_matches_every_pair():
    pairs = _pairs("a", "b", "c")
    plan = plan_run(5, pairs)
    assert plan.pairs == tuple(pairs) and plan.todo == tuple(pairs)
    assert (plan.repeated_rows, plan.skipped, plan.errors_before, plan.retried) == (2, 0, 0, set())


def test_plan_run_skips_the_pairs_done_and_counts_their_errors():
    pairs = _pairs("a", "b", "c", "d")
    # the output holds a, b (an error) and a pair no longer in the CSV, x (an error)
    done = Done(frozenset({("a", "a'"), ("b", "b'"), ("x", "x'")}),
                frozenset({("b", "b'"), ("x", "x'")}), 100)
    plan = plan_run(4, pairs, done)
    assert [p.low for p in plan.todo] == ["c", "d"]
    assert (plan.repeated_rows, plan.skipped, plan.errors_before) == (0, 2, 1)


def test_errors_to_retry_are_the_error_lines_of_the_csv_pairs_only():
    done = Done(frozenset({("a", "a'"), ("b", "b'"), ("x", "x'")}),
                frozenset({("b", "b'"), ("x", "x'")}), 100)
    assert errors_to_retry(done, _pairs("a", "b", "c")) == {("b", "b'")}
    assert errors_to_retry(NOTHING_DONE, _pairs("a")) == frozenset()


def test_resume_output_removes_the_retried_error_lines_and_redoes_only_pairs_without_a_good_line(
        tmp_path):
    good, bad, bad_twice, good_too = (_line("a", "b"), _line("c", "d", error=True),
                                      _line("g", "h", error=True), _line("g", "h"))
    out = write(tmp_path / "r.jsonl", good + bad + bad_twice + good_too)
    config = config_json(Config())
    done = scan_output(out, config)
    retry = errors_to_retry(done, [Pair("c", "d", "c", "d"), Pair("g", "h", "g", "h")])
    assert retry == {("c", "d"), ("g", "h")}
    done, retried = resume_output(out, done, retry, config)
    assert out.read_text() == good + good_too
    assert retried == {("c", "d")}  # ("g", "h") has a good line: kept, not redone
    plan = plan_run(2, [Pair("c", "d", "c", "d"), Pair("g", "h", "g", "h")], done, retried)
    assert [p.key for p in plan.todo] == [("c", "d")] and plan.errors_before == 0


def test_resume_output_without_retries_cuts_a_torn_line_only(tmp_path):
    text = _line("a", "b") + _line("c", "d", error=True)
    out = write(tmp_path / "r.jsonl", text + _line("e", "f")[:30])
    config = config_json(Config())
    done, retried = resume_output(out, scan_output(out, config), frozenset(), config)
    assert out.read_text() == text and retried == frozenset()
    assert done.errors == {("c", "d")}
