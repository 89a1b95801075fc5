"""The command line: help, bad inputs (exit 2, one-line Error), no match (exit 1), the JSON
contract, the demo (exit 0), batch with a bad pair, resume and worker processes."""

from __future__ import annotations

import re

import csv
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from scalematch import __version__
from scalematch.cli import cli, parse_scales

ROOT = Path(__file__).resolve().parents[1]
DEMO_LOW = ROOT / "data" / "demo_low.png"
DEMO_HIGH = ROOT / "data" / "demo_high.png"
HAS_PIPELINE = (ROOT / "scalematch" / "pipeline.py").is_file()
needs_pipeline = pytest.mark.skipif(not HAS_PIPELINE, reason="scalematch/pipeline.py not yet there")

#: Every key of the JSON contract (README.md, "## Output").
JSON_KEYS = {"matched", "reason", "model", "order", "transform", "resolution_ratio", "rotation_deg",
             "translation", "best_scale", "inliers", "matches", "scales", "seconds", "config",
             "version", "low", "high"}
SCALE_KEYS = {"s", "ratio", "points", "initial", "kept", "inliers", "outlier_pct"}


def run(*args: str):
    return CliRunner().invoke(cli, [str(a) for a in args], prog_name="scalematch")


def assert_one_line_error(result, needle: str = "") -> str:
    """Exit 2, no traceback, the last line of stderr is the one-line 'Error: ...'."""
    assert result.exit_code == 2, (result.exit_code, result.output)
    assert "Traceback" not in result.output
    assert not isinstance(result.exception, Exception) or isinstance(result.exception, SystemExit)
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith("Error: "), result.stderr
    assert sum(line.startswith("Error") for line in result.stderr.splitlines()) == 1
    assert needle.lower() in last.lower(), last
    return last


@pytest.fixture
def flat_pair(tmp_path):
    """Two flat grey images: nothing to match (exit 1)."""
    low, high = tmp_path / "flat_low.png", tmp_path / "flat_high.png"
    cv2.imwrite(str(low), np.full((120, 160), 128, np.uint8))
    cv2.imwrite(str(high), np.full((200, 240), 90, np.uint8))
    return low, high


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


def test_version():
    result = run("--version")
    assert result.exit_code == 0 and result.output.strip() == f"scalematch {__version__}"


def test_parse_scales():
    assert parse_scales("1-4") == (1.0, 2.0, 3.0, 4.0)
    assert parse_scales("2-4:0.5") == (2.0, 2.5, 3.0, 3.5, 4.0)
    assert parse_scales("1,2,3.5") == (1.0, 2.0, 3.5)
    assert parse_scales("1-3, 8") == (1.0, 2.0, 3.0, 8.0)
    for bad in ("8-1", "a-b", "0.5-2", "", "1-4:0", "2:3"):
        with pytest.raises(ValueError):
            parse_scales(bad)


# --------------------------------------------------------------------------- bad input: exit 2

def _bad_input(tmp_path: Path, case: str):
    """(args, expected text in the Error line) for one kind of bad input."""
    good = tmp_path / "good.png"
    img = cv2.imread(str(DEMO_HIGH), cv2.IMREAD_GRAYSCALE)
    cv2.imwrite(str(good), img)
    bad = tmp_path / "bad.png"
    if case == "missing":
        return [tmp_path / "nope.png", good], "does not exist"
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
    if case == "unwritable_json":
        return [good, good, "--json", tmp_path / "no" / "such" / "r.json"], "does not exist"
    if case == "bad_scales":
        return [good, good, "--scales", "8-1"], "scales"
    if case == "bad_set":
        return [good, good, "--set", "harris.nope=3"], "no parameter"
    if case == "bad_set_value":
        return [good, good, "--set", "harris.threshold=abc"], "float"
    raise AssertionError(case)


@pytest.mark.parametrize("case", ["missing", "directory", "empty", "truncated", "text", "tiny",
                                  "too_many_pixels", "unwritable_out_dir", "unwritable_json",
                                  "bad_scales", "bad_set", "bad_set_value"])
def test_bad_input_exits_2_with_one_line_error(tmp_path, case):
    args, needle = _bad_input(tmp_path, case)
    assert_one_line_error(run(*args), needle)


def test_over_the_limit_message_names_size_and_limit(tmp_path):
    args, _ = _bad_input(tmp_path, "too_many_pixels")
    last = assert_one_line_error(run(*args))
    assert "480x360" in last and "limit" in last


def test_unknown_option_is_a_usage_error(flat_pair):
    result = run(*flat_pair, "--no-such-option")
    assert result.exit_code == 2 and "No such option" in result.output


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
    assert data["inliers"] == 0 and data["matches"] == []
    assert data["low"] == {"path": str(flat_pair[0]), "width": 160, "height": 120}
    assert data["high"]["width"] == 240 and data["version"] == __version__
    assert data["config"]["model"] == "similarity"
    for name in ("overlay.png", "scales.png", "matches.csv"):
        assert (out / name).is_file(), name
    assert cv2.imread(str(out / "overlay.png")).shape == (120, 160, 3)


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
    assert len(data["scales"]) == len(data["config"]["scales"])
    assert SCALE_KEYS <= set(data["scales"][0])
    assert data["best_scale"] in [row["s"] for row in data["scales"]]
    assert data["seconds"] > 0
    assert "matched" in result.stderr
    said = re.search(r"ratio (\d+\.\d+)", result.stderr)
    assert said and abs(float(said.group(1)) - 3.0) < 0.05, result.stderr
    with open(out / "matches.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["x_high", "y_high", "x_low", "y_low"] and len(rows) == data["inliers"] + 1
    low = cv2.imread(str(DEMO_LOW))
    assert cv2.imread(str(out / "overlay.png")).shape == low.shape
    assert (out / "matches.png").is_file() and (out / "scales.png").is_file()


# --------------------------------------------------------------------------- batch

def _write_csv(path: Path, rows, header: bool = True) -> Path:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        if header:
            w.writerow(["low", "high"])
        w.writerows(rows)
    return path


@needs_pipeline
def test_batch_good_and_bad_pair(tmp_path):
    shutil.copy(DEMO_LOW, tmp_path / "low.png")
    shutil.copy(DEMO_HIGH, tmp_path / "high.png")
    pairs = _write_csv(tmp_path / "pairs.csv", [["low.png", "high.png"],
                                                ["low.png", "missing.png"]], header=False)
    result = run("batch", pairs, "-q")
    assert result.exit_code == 0, result.output
    lines = [json.loads(x) for x in result.stdout.splitlines()]
    assert len(lines) == 2
    good, bad = lines
    assert good["matched"] is True and JSON_KEYS <= set(good) and "error" not in good
    assert good["low"]["path"] == "low.png"
    assert bad["matched"] is False and "missing.png" in bad["error"]
    assert bad["high"]["path"] == "missing.png"


@needs_pipeline
def test_batch_resume_skips_done_pairs_and_cuts_a_torn_line(tmp_path, flat_pair):
    low, high = flat_pair
    out = tmp_path / "results.jsonl"
    pairs = _write_csv(tmp_path / "pairs.csv", [[low, high], [high, low]])
    assert run("batch", pairs, "--output", out, "-q").exit_code == 0
    first = out.read_text().splitlines()
    assert len(first) == 2
    # an interruption tore a third line; then the CSV grows by one pair
    with open(out, "a") as fh:
        fh.write('{"low": {"path": "x"}, "matc')
    _write_csv(pairs, [[low, high], [high, low], [low, tmp_path / "gone.png"]])
    result = run("batch", pairs, "--output", out)
    assert result.exit_code == 0, result.output
    lines = out.read_text().splitlines()
    assert lines[:2] == first  # done pairs are neither redone nor rewritten
    assert len(lines) == 3 and "gone.png" in json.loads(lines[2])["error"]
    assert "resuming: 2 of 3" in result.stderr
    # everything done: a third run adds nothing
    assert run("batch", pairs, "--output", out, "-q").exit_code == 0
    assert out.read_text().splitlines() == lines


@needs_pipeline
def test_batch_with_worker_processes(tmp_path, flat_pair):
    low, high = flat_pair
    text = tmp_path / "text.png"
    text.write_text("not an image")
    pairs = _write_csv(tmp_path / "pairs.csv", [[low, high], [text, high], [low, text]])
    result = run("batch", pairs, "--jobs", "2", "-q")
    assert result.exit_code == 0, result.output
    lines = [json.loads(x) for x in result.stdout.splitlines()]
    assert len(lines) == 3
    assert sorted("error" in x for x in lines) == [False, True, True], result.stdout
    ok = next(x for x in lines if "error" not in x)
    assert ok["matched"] is False and ok["reason"]


def test_batch_bad_csv_exits_2(tmp_path):
    bad = tmp_path / "pairs.csv"
    bad.write_text("only-one-column\n")
    assert_one_line_error(run("batch", bad), "two paths")
