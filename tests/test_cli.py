"""The command line: help, bad inputs (exit 2, one-line Error), option values that mean nothing,
Ctrl-C (exit 130), no match (exit 1), the JSON contract, the demo (exit 0). Batch: test_batch.py;
what the options give, the outputs checked, stderr's words: test_options.py, test_outputs.py,
test_report.py."""

from __future__ import annotations

import csv
import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from scalematch import __version__
from scalematch.cli import cli

ROOT = Path(__file__).resolve().parents[1]
DEMO_LOW = ROOT / "data" / "demo_low.png"
DEMO_HIGH = ROOT / "data" / "demo_high.png"
HAS_PIPELINE = (ROOT / "scalematch" / "pipeline.py").is_file()
needs_pipeline = pytest.mark.skipif(not HAS_PIPELINE, reason="scalematch/pipeline.py not yet there")

#: Every key of the JSON contract (README.md, "## Output").
JSON_KEYS = {"matched", "reason", "model", "order", "transform", "resolution_ratio", "rotation_deg",
             "translation", "best_scale", "n_inliers", "inliers", "matches", "scales", "seconds", "config",
             "version", "low", "high"}
SCALE_KEYS = {"s", "ratio", "points", "initial", "kept", "inliers", "outlier_pct"}


def run(*args: str):
    return CliRunner().invoke(cli, [str(a) for a in args], prog_name="scalematch")


def assert_one_line_error(result, needle: str = "") -> str:
    """Exit 2, no traceback, stderr is the one line 'Error: ...' (no usage block)."""
    assert result.exit_code == 2, (result.exit_code, result.output)
    assert "Traceback" not in result.output
    assert not isinstance(result.exception, Exception) or isinstance(result.exception, SystemExit)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    last = lines[0]
    assert last.startswith("Error: "), result.stderr
    assert needle.lower() in last.lower(), last
    return last


# --------------------------------------------------------------------------- help and version

def test_help_shows_examples_and_exit_codes():
    for args in ([], ["--help"], ["match", "--help"], ["batch", "--help"]):
        result = run(*args)
        text = result.output
        assert "Examples:" in text and "scalematch" in text, args
        assert "Exit codes" in text, args
    top = run("--help").output
    assert "match" in top and "batch" in top
    opts = run("match", "--help").output
    for opt in ("--out-dir", "--json", "--model", "--mode", "--scales", "--seed", "--quiet",
                "--verbose", "--max-pixels", "--harris-threshold", "--set"):
        assert opt in opts, opt


def test_each_command_says_what_its_own_exit_codes_mean():
    match_help = " ".join(run("match", "--help").output.split())
    batch_help = " ".join(run("batch", "--help").output.split())
    assert "0 matched 1 no reliable match" in match_help
    assert "batch" not in match_help.split("Exit codes")[1]  # the batch's meanings stay there
    assert "0 every pair has its line, none an error" in batch_help
    assert "a pair's missing or bad image is its error line (exit 3)" in batch_help
    # a pair's "no" is its line: the batch has no exit 1 (a closed pipe is 141, test_exits.py)
    batch_codes = batch_help.split("Exit codes")[1].split("Options:")[0]
    assert " 1 " not in batch_codes and "a batch never exits 1" in batch_codes
    for text in (match_help, batch_help):
        assert "130 interrupted (Ctrl-C) 141 the output pipe was closed" in text


def test_no_arguments_print_the_help_and_examples_without_error():
    result = run()
    assert result.exit_code == 2  # a usage error: nothing to do
    assert "Error" not in result.output
    assert result.stderr.startswith("Usage: scalematch") and "Examples:" in result.stderr
    assert "Exit codes:" in result.stderr


def test_min_inliers_help_says_fewer_pass_with_the_pixel_check():
    from scalematch.config import Config

    text = " ".join(run("match", "--help").output.split())
    few = Config().decision.few_min_inliers
    assert f"with fewer, down to {few}, a match is accepted only when it is far beyond chance " \
           "and the pixel check confirms it" in text


def test_the_names_other_trees_import_from_the_command_line_stay_there():
    """``scalematch lab regress --tree`` and scripts/no_price.py import ``main`` and
    ``set_path`` from ``scalematch.cli``, in this tree as in older ones."""
    from scalematch import cli, options

    assert callable(cli.main) and cli.set_path is options.set_path


def test_python_dash_m_runs_the_command_line():
    out = subprocess.run([sys.executable, "-m", "scalematch", "--version"], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == f"scalematch {__version__}"


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full (a full disk)")
def test_json_to_a_full_stdout_is_an_input_error_as_to_a_full_file():
    """``--json -`` to a stdout that cannot take it exits 2 with one line, as ``--json FILE``
    does (it was an internal error, exit 4)."""
    with open("/dev/full", "w") as full:
        out = subprocess.run([sys.executable, "-m", "scalematch", str(DEMO_LOW), str(DEMO_HIGH),
                              "--json", "-", "-q"], stdout=full, stderr=subprocess.PIPE,
                             text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    assert out.stderr.strip().splitlines() == [
        "Error: cannot write --json to stdout: No space left on device"]


def test_nodata_takes_auto_none_or_a_grey_level_and_the_json_records_it(tmp_path):
    """``--nodata`` as GDAL declares no-data: a level, or "none"; a word is a usage error."""
    bad = run(DEMO_LOW, DEMO_HIGH, "--nodata", "black")
    assert bad.exit_code == 2
    assert_one_line_error(bad, "--nodata must be auto, none or a grey level")
    for level in ("300", "-5"):  # the images are matched as 8-bit grey: 0 to 255
        beyond = run(DEMO_LOW, DEMO_HIGH, "--nodata", level)
        assert beyond.exit_code == 2
        assert_one_line_error(beyond, "--nodata must be a grey level from 0 to 255")
    data = json.loads(run(DEMO_LOW, DEMO_HIGH, "--nodata", "none", "--json", "-", "-q").stdout)
    assert data["config"]["nodata"]["rule"] == "none" and data["matched"]
    assert data["low"]["nodata"] == data["high"]["nodata"] == {"value": None, "share": 0.0}
    auto = json.loads(run(DEMO_LOW, DEMO_HIGH, "--json", "-", "-q").stdout)
    # the demo's low image is the shrunk photo turned 25 degrees on a black canvas
    assert auto["low"]["nodata"]["value"] == 0.0 and 0.3 < auto["low"]["nodata"]["share"] < 0.5
    level = json.loads(run(DEMO_LOW, DEMO_HIGH, "--set", "nodata.rule=0", "--json", "-",
                           "-q").stdout)
    assert level["config"]["nodata"]["rule"] == 0.0 and level["matched"]


def test_version():
    result = run("--version")
    assert result.exit_code == 0 and result.output.strip() == f"scalematch {__version__}"


@needs_pipeline
def test_scales_out_of_reach_exit_1_with_the_reason(tmp_path):
    """The demo's high image is 480 px wide: at scale 16 it would span 30 coarser px, under the
    smallest footprint (32), so nothing is searched: an answer about the images (exit 1)."""
    result = run(DEMO_LOW, DEMO_HIGH, "--scales", "16", "--json", "-", "-q", "-o", tmp_path)
    assert result.exit_code == 1, result.output
    answer = json.loads(result.stdout)
    assert not answer["matched"] and answer["reason"].startswith("no scale searched fits")
    assert answer["scales"] == []


def test_time_budget_inf_is_no_limit(flat_pair):
    result = run(*flat_pair, "--time-budget", "inf", "--json", "-", "-q")
    assert result.exit_code == 1, result.output  # flat images: searched in full, no match
    answer = json.loads(result.output)
    assert answer["config"]["time_budget_s"] is None
    assert answer["evidence"]["stopped"] != "time budget"


# --------------------------------------------------------------------------- bad input: exit 2

def _bad_input(tmp_path: Path, case: str):
    """(args, expected text in the Error line) for one kind of bad input."""
    good = tmp_path / "good.png"
    img = cv2.imread(str(DEMO_HIGH), cv2.IMREAD_GRAYSCALE)
    cv2.imwrite(str(good), img)
    bad = tmp_path / "bad.png"
    if case == "missing":
        return [tmp_path / "nope.png", good], "no such file"
    if case == "directory":
        return [tmp_path, good], "directory"
    if case == "empty":
        bad.write_bytes(b"")
        return [bad, good], "empty"
    if case == "truncated":
        data = cv2.imencode(".png", img)[1].tobytes()
        bad.write_bytes(data[: len(data) // 3])
        return [good, bad], "truncated"
    if case == "text":
        bad.write_text("low,high\nthis is a text file\n")
        return [bad, good], "not an image"
    if case == "tiny":
        cv2.imwrite(str(bad), img[:16, :200])
        return [good, bad], "too small"
    if case == "too_many_pixels":
        return [good, good, "--max-pixels", "1000"], "--max-pixels"
    if case == "unwritable_out_dir":
        blocker = tmp_path / "file.txt"
        blocker.write_text("a file, not a folder")
        return [good, good, "--out-dir", blocker / "out"], "--out-dir"
    if case == "unwritable_json":  # its folder would be a file
        blocker = tmp_path / "file.txt"
        blocker.write_text("a file, not a folder")
        return [good, good, "--json", blocker / "r.json"], "cannot write --json"
    if case == "bad_scales":
        return [good, good, "--scales", "8-1"], "scales"
    if case == "bad_set":
        return [good, good, "--set", "harris.nope=3"], "no parameter 'harris.nope'"
    if case == "bad_set_group":
        return [good, good, "--set", "harris=3"], "is a group of parameters"
    if case == "bad_set_value":
        return [good, good, "--set", "harris.threshold=abc"], "float"
    if case == "constant":
        cv2.imwrite(str(bad), np.full((120, 160), 128, np.uint8))
        return [bad, good], "constant"
    raise AssertionError(case)


@pytest.mark.parametrize("case", ["missing", "directory", "empty", "truncated", "text", "tiny",
                                  "too_many_pixels", "unwritable_out_dir", "unwritable_json",
                                  "bad_scales", "bad_set", "bad_set_group", "bad_set_value",
                                  "constant"])
def test_bad_input_exits_2_with_one_line_error(tmp_path, case):
    args, needle = _bad_input(tmp_path, case)
    assert_one_line_error(run(*args), needle)


def test_over_the_limit_message_names_size_and_limit(tmp_path):
    args, _ = _bad_input(tmp_path, "too_many_pixels")
    last = assert_one_line_error(run(*args))
    assert "480x360" in last and "limit" in last


@pytest.mark.parametrize("case", ["missing", "text", "constant"])
def test_json_of_an_input_error_says_why_as_a_batch_line_does(tmp_path, case):
    """``--json -`` of a pair that cannot be matched: its error, not nothing (exit 2)."""
    args, needle = _bad_input(tmp_path, case)
    result = run(*args, "--json", "-", "-q")
    assert result.exit_code == 2
    data = json.loads(result.stdout)
    assert data["matched"] is False and data["error_kind"] == "input"
    assert needle.lower() in data["error"].lower() and data["low"]["path"] == str(args[0])


def test_a_mistyped_command_is_named_as_such(tmp_path):
    last = assert_one_line_error(run("mtch", str(tmp_path / "a.png"), "b.png"), "'mtch'")
    assert "did you mean 'match'?" in last


def test_unknown_option_is_a_usage_error(flat_pair):
    last = assert_one_line_error(run(*flat_pair, "--no-such-option"), "No such option")
    assert "--help" in last  # where to look, in place of click's usage block


#: Option values that mean nothing: (option, value, what the message names).
#: The message is the library's (scalematch.checks), the same for an option and for --set.
MEANINGLESS = [("--ransac-threshold", "-1", "ransac.threshold_px must be > 0"),
               ("--ransac-threshold", "0", "ransac.threshold_px must be > 0"),
               ("--ransac-threshold", "nan", "ransac.threshold_px must be > 0, got nan"),
               ("--ratio-test", "1.5", "matcher.ratio must be in (0, 1]"),
               ("--ratio-test", "0", "matcher.ratio must be in (0, 1]"),
               ("--ransac-iterations", "0", "ransac.max_iters must be an integer in [1, 100000]"),
               # options that multiply the work are bounded at the door, named
               ("--ransac-iterations", "1000000",
                "--ransac-iterations 1000000: ransac.max_iters must be an integer in [1, 100000]"),
               ("--scales", "1-16:0.001", "--scales 1-16:0.001: scales '1-16:0.001' are 15001 "
                                          "scales, more than the 64 searched at most"),
               ("--scales", "1-1e300:0.5", "more than the 64 searched at most"),
               # a count beyond a million said in its order of magnitude, not 300 digits
               ("--scales", "1-16:1e-300", "are about 1.5e+301 scales, more than the 64"),
               ("--scales", "1-16:1e-320", "are more scales than a float can count"),
               ("--scales", "1-inf", "--scales 1-inf: scales '1-inf' are not finite numbers"),
               ("--scales", ",".join(str(1 + k / 10) for k in range(65)),
                "scales: at most 64 are searched, got 65"),
               ("--scales", "0", "--scales 0: scales must be >= 1, got 0.0"),
               ("--set", "views.longitude_step_deg=1", "--set views.longitude_step_deg=1: views: "
                                                       "the passes hold 3600 views"),
               ("--set", "scales=0", "--set scales=0: scales must be >= 1"),
               ("--working-size", "-3", "--working-size must be 0 (always full size) or at "
                                        "least 64 px, got -3"),
               ("--harris-threshold", "-5", "harris.threshold must be >= 0"),
               ("--min-inliers", "-1", "decision.min_inliers must be an integer in [0, 2147483647]"),
               ("--max-log-nfa", "inf", "decision.max_log_nfa must be a finite number"),
               ("--set", "ransac.threshold_px=-1", "ransac.threshold_px"),
               ("--set", "matcher.ratio=2", "matcher.ratio"),
               ("--time-budget", "0", "--time-budget must be more than 0 seconds"),
               ("--set", "time_budget_s=-2", "time_budget_s must be > 0"),
               # OpenCV's random generator takes a C int: 2^31 and 2^63 (a seed from
               # `date +%s%N`) were exit 4 or "integer won't fit into a C int"
               ("--seed", "9223372036854775808",
                "'--seed': 9223372036854775808 is not in the range 0<=x<=2147483647"),
               ("--seed", "2147483648", "'--seed': 2147483648 is not in the range"),
               ("--seed", "-1", "'--seed': -1 is not in the range"),
               ("--set", "seed=9223372036854775808",
                "seed must be an integer in [0, 2147483647], got 9223372036854775808"),
               ("--set", "seed=2147483648", "seed must be an integer in [0, 2147483647]")]


@pytest.mark.parametrize("command", ["match", "batch"])
@pytest.mark.parametrize("option,value,needle", MEANINGLESS)
def test_meaningless_option_values_are_usage_errors(tmp_path, flat_pair, command, option, value,
                                                    needle):
    pairs = tmp_path / "pairs.csv"
    pairs.write_text(f"{flat_pair[0]},{flat_pair[1]}\n")
    args = [command, *flat_pair] if command == "match" else [command, pairs]
    assert_one_line_error(run(*args, option, value), needle)


def test_the_working_size_help_gives_the_values_taken():
    text = run("match", "--help").output
    assert "0 (always full size) or at least 64" in " ".join(text.split())
    assert "x>=0" not in text  # 1 to 63 are refused: the range shown would mislead


def test_the_group_help_says_where_the_options_are():
    text = " ".join(run("--help").output.split())
    assert "scalematch match --help" in text and "scalematch batch --help" in text


def test_quiet_and_verbose_together_are_a_usage_error(flat_pair):
    assert_one_line_error(run(*flat_pair, "-q", "-v"), "-q (--quiet) and -v (--verbose) "
                                                       "exclude each other")


def test_help_is_a_command_not_a_file_to_match():
    result = run("help")
    assert result.exit_code == 0 and result.output == run("--help").output
    result = run("help", "batch")
    assert result.exit_code == 0 and result.output == run("batch", "--help").output
    assert_one_line_error(run("help", "bach"), "no command 'bach'; the commands: match, batch")


def test_a_constant_image_is_named_and_leaves_no_out_dir(tmp_path):
    args, _ = _bad_input(tmp_path, "constant")
    out = tmp_path / "out" / "demo"
    last = assert_one_line_error(run(*args, "-o", out))
    assert last == (f"Error: {args[0]}: image is constant (every pixel 128): there is nothing "
                    f"to match in it")
    assert not (tmp_path / "out").exists()


def test_a_tiff_whose_first_page_is_blank_says_it_has_pages(tmp_path):
    """OpenCV decodes a TIFF's first page only: a blank first page (the page the user looks at
    is another) is exit 2 in one line that says how many pages the file has, which one was
    read and what to do; a one-page constant TIFF is refused in the words of any constant
    image."""
    texture = cv2.imread(str(DEMO_LOW), cv2.IMREAD_GRAYSCALE)
    pages = tmp_path / "pages.tif"
    assert cv2.imwritemulti(str(pages), [np.zeros_like(texture), texture])
    last = assert_one_line_error(run(pages, DEMO_HIGH, "-q"))
    assert last == (f"Error: {pages}: image is constant (every pixel 0): there is nothing to "
                    f"match in it; the file is a TIFF of 2 pages and only the first is read: "
                    f"save the page wanted as an image file of its own")
    one = tmp_path / "one.tif"
    assert cv2.imwrite(str(one), np.zeros_like(texture))
    last = assert_one_line_error(run(one, DEMO_HIGH, "-q"))
    assert last == f"Error: {one}: image is constant (every pixel 0): there is nothing to match in it"


def test_a_refused_match_removes_the_out_dir_it_made(tmp_path, monkeypatch, flat_pair):
    """An input the match itself refuses (after the folders of -o are made) leaves none of
    them behind; a folder that was there stays."""
    def refused(*args, **kwargs):
        raise ValueError("refused by the pipeline")

    monkeypatch.setattr("scalematch.cli._run_match", refused)
    assert_one_line_error(run(*flat_pair, "-o", tmp_path / "a" / "b"), "refused")
    assert not (tmp_path / "a").exists()
    (tmp_path / "kept").mkdir()
    assert_one_line_error(run(*flat_pair, "-o", tmp_path / "kept" / "b"), "refused")
    assert (tmp_path / "kept").is_dir() and not (tmp_path / "kept" / "b").exists()


def test_ctrl_c_while_the_command_line_loads_is_one_line_and_exit_130(tmp_path):
    """Ctrl-C in the first 0.1 s, while numpy, OpenCV and click load, printed a 20-line
    traceback of the imports. The interrupt is raised here where the command line's module
    is imported, as a signal would raise it there."""
    probe = ("import sys\n"
             "class Interrupt:\n"
             "    def find_spec(self, name, path=None, target=None):\n"
             "        if name == 'scalematch.cli':\n"
             "            raise KeyboardInterrupt\n"
             "sys.meta_path.insert(0, Interrupt())\n"
             "from scalematch.__main__ import main\n"
             "main()\n")
    done = subprocess.run([sys.executable, "-c", probe, str(DEMO_LOW), str(DEMO_HIGH)],
                          capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert (done.returncode, done.stderr) == (130, "interrupted\n")


def test_ctrl_c_in_match_exits_130(monkeypatch, flat_pair):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("scalematch.cli._run_match", interrupted)
    result = run(*flat_pair, "-q")
    assert result.exit_code == 130, (result.exit_code, result.output)
    assert result.stderr.strip() == "interrupted"
    assert "130  interrupted" in run("match", "--help").output


# --------------------------------------------------------------------------- no match: exit 1

@needs_pipeline
def test_flat_images_no_reliable_match_and_json_still_written(tmp_path, flat_pair):
    out = tmp_path / "out"
    js = tmp_path / "result.json"
    result = run(*flat_pair, "--out-dir", out, "--json", js)
    assert result.exit_code == 1, result.output
    assert "no reliable match" in result.stderr and "Traceback" not in result.output
    data = json.loads(js.read_text())
    assert JSON_KEYS <= set(data)
    assert data["matched"] is False and data["reason"] and data["transform"] is None
    assert data["n_inliers"] == data["inliers"] == 0 and data["matches"] == []
    assert data["best_scale"] is None and data["resolution_ratio"] is None  # as GUIDE says
    assert data["low"] == {"path": str(flat_pair[0]), "width": 160, "height": 120,
                           "nodata": {"value": None, "share": 0.0}, "warning": None}
    assert data["high"]["width"] == 240 and data["version"] == __version__
    assert data["config"]["model"] == "similarity"
    for name in ("overlay.png", "scales.png", "matches.csv"):
        assert (out / name).is_file(), name
    # the low image enlarged 4 times (under 600 px: overlay.MIN_OVERLAY_SIDE_PX)
    overlay_shape = cv2.imread(str(out / "overlay.png")).shape
    assert overlay_shape[1:] == (640, 3) and overlay_shape[0] >= 480


# --------------------------------------------------------------------------- the demo: exit 0

@needs_pipeline
def test_demo_pair_matches_with_full_json_and_pictures(tmp_path):
    out = tmp_path / "demo"
    # the default command: no "match" in the arguments
    result = run(DEMO_LOW, DEMO_HIGH, "--out-dir", out, "--json", "-")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert JSON_KEYS <= set(data)
    assert data["matched"] is True and data["reason"] is None
    # data/SOURCES.md: ratio 3, rotation 25 degrees, translation (213.80, 104.48)
    assert abs(data["resolution_ratio"] - 3.0) < 0.05
    assert abs(data["rotation_deg"] - 25.0) < 0.5
    assert np.allclose(data["translation"], [213.80, 104.48], atol=1.5)
    assert np.asarray(data["transform"]).shape == (2, 3)
    assert data["inliers"] == len(data["matches"]) >= 20
    assert all(len(m) == 4 for m in data["matches"])
    # the table: every configured scale at which the 480 px high image spans 32+ low px
    reach = [s for s in data["config"]["scales"] if 480 / s >= data["config"]["min_footprint_px"]]
    assert [row["s"] for row in data["scales"]] == reach
    assert SCALE_KEYS <= set(data["scales"][0])
    assert data["best_scale"] in [row["s"] for row in data["scales"]]
    assert data["seconds"] > 0
    assert "matched" in result.stderr
    # the time the summary gives is the match's, as the JSON's "seconds"
    assert f"wrote overlay.png, matches.png, scales.png, matches.csv in {out}" in result.stderr
    took = re.search(r"; matching took (\d+\.\d\d) s$", result.stderr.strip())
    assert took and float(took.group(1)) == pytest.approx(data["seconds"], abs=0.006)
    said = re.search(r"ratio (\d+\.\d+)", result.stderr)
    assert said and abs(float(said.group(1)) - 3.0) < 0.05, result.stderr
    with open(out / "matches.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["x_high", "y_high", "x_low", "y_low"] and len(rows) == data["inliers"] + 1
    low = cv2.imread(str(DEMO_LOW))  # 419 px wide: drawn twice as large, between captions
    drawn = cv2.imread(str(out / "overlay.png")).shape
    assert drawn[1:] == (2 * low.shape[1], 3) and drawn[0] > 2 * low.shape[0] + 50
    assert (out / "matches.png").is_file() and (out / "scales.png").is_file()


@needs_pipeline
def test_working_size_and_order_options_reach_the_config(tmp_path):
    # demo_low is 419 px wide: a working size of 400 px shrinks it, 0 keeps the full size
    shrunk = run(DEMO_LOW, DEMO_HIGH, "--working-size", "400", "--json", "-", "-q")
    assert shrunk.exit_code == 0, shrunk.output
    d = json.loads(shrunk.stdout)
    assert d["config"]["low_max_side"] == 400 and d["evidence"]["low_working_factor"] > 1
    full = json.loads(run(DEMO_LOW, DEMO_HIGH, "--working-size", "0", "--json", "-", "-q").stdout)
    assert full["config"]["low_max_side"] is None
    # the answer is in the original low pixels either way (within a pixel)
    a, b = np.array(d["transform"]), np.array(full["transform"])
    assert np.abs(a[:, 2] - b[:, 2]).max() < 1.0 and abs(d["resolution_ratio"] /
                                                          full["resolution_ratio"] - 1) < 0.01
    swapped = json.loads(run(DEMO_HIGH, DEMO_LOW, "--json", "-", "-q").stdout)
    assert swapped["order"] == "swapped" and swapped["low"]["path"].endswith("demo_low.png")
    given = run(DEMO_HIGH, DEMO_LOW, "--order", "given", "--no-views", "--json", "-", "-q")
    assert given.exit_code == 1 and json.loads(given.stdout)["config"]["order"] == "given"


def test_a_working_size_too_small_names_the_option(tmp_path):
    """--working-size below the minimum is a usage error in the option's own words (exit 2)."""
    from scalematch.config import MIN_WORKING_SIDE_PX

    low, high = str(ROOT / "data" / "demo_low.png"), str(ROOT / "data" / "demo_high.png")
    result = CliRunner().invoke(cli, ["match", low, high, "--working-size", "10"])
    assert result.exit_code == 2
    assert f"--working-size must be 0 (always full size) or at least {MIN_WORKING_SIDE_PX} px" \
        in result.output and "low_max_side" not in result.output


# --------------------------------------------------------------------------- unexpected errors: 4

def test_an_unexpected_error_exits_4_with_one_line_and_the_traceback_with_v(monkeypatch,
                                                                             flat_pair):
    def broken(*args, **kwargs):
        raise RuntimeError("a bug")

    monkeypatch.setattr("scalematch.cli._run_match", broken)
    quiet = run(*flat_pair, "-q")
    assert quiet.exit_code == 4, (quiet.exit_code, quiet.output)
    assert quiet.stderr.strip().splitlines() == [
        "Error: internal error, RuntimeError: a bug (-v shows the traceback)"]
    loud = run(*flat_pair, "-v")
    assert loud.exit_code == 4
    assert "Traceback" in loud.stderr and "RuntimeError: a bug" in loud.stderr
    assert loud.stderr.strip().splitlines()[-1] == "Error: internal error, RuntimeError: a bug"
    help_text = run("match", "--help").output
    assert "4  unexpected error" in help_text and "1  no reliable match" in help_text


#: Address space of the command under test: Python, numpy and OpenCV start in it (a refused
#: input takes about 60 MB, measured), a 12 MP match at full size (about 1.5 GB) does not fit.
MATCH_LIMIT_AS_BYTES = 700 << 20


def run_limited(*args: Any, timeout: float = 120):
    """The command line in a subprocess with its address space limited by ``resource.setrlimit``
    in the child (never on the machine)."""
    import resource
    import subprocess
    import sys

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (MATCH_LIMIT_AS_BYTES, MATCH_LIMIT_AS_BYTES))

    return subprocess.run([sys.executable, "-m", "scalematch.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, preexec_fn=limit)


@pytest.fixture(scope="module")
def big_pair(tmp_path_factory):
    """A 4000x3000 textured image and its half: matched at full size, more than the limit."""
    folder = tmp_path_factory.mktemp("big")
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur((rng.random((3000, 4000)) * 255).astype(np.uint8), (0, 0), 2)
    cv2.imwrite(str(folder / "big.png"), img)
    cv2.imwrite(str(folder / "half.png"), img[::2, ::2].copy())
    return folder / "half.png", folder / "big.png"


@needs_pipeline
def test_out_of_memory_exits_4_not_1(big_pair):
    quiet = run_limited(*big_pair, "--working-size", "0", "-q")
    lines = quiet.stderr.strip().splitlines()
    assert quiet.returncode == 4, (quiet.returncode, quiet.stderr)
    assert len(lines) == 1 and lines[0].startswith("Error: internal error, out of memory")
    assert lines[0].endswith("(-v shows the traceback)")
    loud = run_limited(*big_pair, "--working-size", "0", "-v")
    assert loud.returncode == 4 and "Traceback (most recent call last)" in loud.stderr


@needs_pipeline
def test_out_of_memory_still_writes_the_json_error_record(big_pair, tmp_path):
    js = tmp_path / "out" / "result.json"
    limited = run_limited(*big_pair, "--working-size", "0", "-q", "--json", js)
    assert limited.returncode == 4, (limited.returncode, limited.stderr)
    record = json.loads(js.read_text())
    assert record["matched"] is False and record["error_kind"] == "internal"
    assert record["error"].startswith("internal error, out of memory")
    assert record["low"]["path"] == str(big_pair[0])


def test_an_unexpected_error_is_recorded_in_the_json_and_ctrl_c_is_not(monkeypatch, flat_pair,
                                                                        tmp_path):
    def broken(*args, **kwargs):
        raise RuntimeError("a bug")

    monkeypatch.setattr("scalematch.cli._run_match", broken)
    js = tmp_path / "result.json"
    assert run(*flat_pair, "-q", "--json", js).exit_code == 4
    record = json.loads(js.read_text())
    assert (record["error_kind"], record["error"]) == ("internal",
                                                       "internal error, RuntimeError: a bug")

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("scalematch.cli._run_match", stopped)
    js2 = tmp_path / "interrupted.json"
    assert run(*flat_pair, "-q", "--json", js2).exit_code == 130
    assert not js2.exists()


# --------------------------------------------------------------------------- a large JPEG


@needs_pipeline
def test_a_jpeg_above_twice_the_working_size_is_decoded_reduced(tmp_path):
    """demo_low as a JPEG (419 px) with a working size of 200 px: decoded at half size (209 px
    >= 200), the answer in the file's pixels, the same as the PNG's within a pixel; the JSON
    names the file's size, the overlay is drawn on the image as decoded."""
    low = tmp_path / "low.jpg"
    cv2.imwrite(str(low), cv2.imread(str(DEMO_LOW)), [cv2.IMWRITE_JPEG_QUALITY, 95])
    out = tmp_path / "out"
    jpeg = run(low, DEMO_HIGH, "--working-size", "200", "--json", "-", "-q", "-o", out)
    png = run(DEMO_LOW, DEMO_HIGH, "--working-size", "200", "--json", "-", "-q")
    assert jpeg.exit_code == 0 and png.exit_code == 0, jpeg.output
    a, b = json.loads(jpeg.stdout), json.loads(png.stdout)
    assert (a["low"]["width"], a["low"]["height"]) == (419, 377)
    assert a["evidence"]["low_working_factor"] == pytest.approx(419 / 200, rel=0.01)
    corners = np.array([[[0.0, 0.0], [479.0, 0.0], [0.0, 359.0], [479.0, 359.0]]])
    gap = np.linalg.norm(cv2.transform(corners, np.array(a["transform"]))
                         - cv2.transform(corners, np.array(b["transform"])), axis=2)
    assert gap.max() < 1.0
    # decoded ceil(419 / 2) = 210 px wide, then drawn 3 times as large (under 600 px)
    overlay_shape = cv2.imread(str(out / "overlay.png")).shape
    assert overlay_shape[1] == 630 and overlay_shape[0] >= 3 * 189
    rows = list(csv.reader(open(out / "matches.csv")))[1:]  # in the file's pixels
    pts = np.array(rows, float)
    fit = cv2.transform(pts[None, :, :2], np.array(a["transform"]))[0]
    assert np.linalg.norm(fit - pts[:, 2:], axis=1).max() < 2.1 * 3.0 + 1e-6


