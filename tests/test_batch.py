"""Batch: the lines counted by verdict, bounded in-flight work, and the command: exit codes (3
when a pair errored), resume and --retry-errors, worker processes that die with the main process
(kill -9), resume after it, a worker killed mid-run (the pool started again, its pairs retried),
no semaphore left to the resource tracker after kill -9, Ctrl-C, and the Dask backend on a
LocalCluster on loopback. The pairs CSV: test_batchcsv.py; the output file and a run's plan:
test_batchresume.py; the worker processes: test_batchpool.py."""

from __future__ import annotations

import concurrent.futures
import json
import os
import shutil
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from scalematch import batch, batchpool
from scalematch.batch import match_pair as real_match_pair  # the worker's own
from scalematch.batch import Counts, Pair, bounded
from scalematch.config import Config
from scalematch.imagefile import DEFAULT_MAX_PIXELS
from scalematch.lab.synthetic import make_zoom_pair
from test_cli import JSON_KEYS, assert_one_line_error, run

#: (width, height) of the tiny synthetic pairs, px: a match takes ~0.1 s.
TINY = (200, 150)
#: Zoom of the tiny pairs (high px per low px).
RATIO = 2.5


@pytest.fixture(scope="module")
def images(raccoon, tmp_path_factory) -> Path:
    """A folder with a tiny zoom pair (low.png, high.png; ratio 2.5) and a noise pair with
    nothing to match (noise_low.png, noise_high.png)."""
    folder = tmp_path_factory.mktemp("images")
    pair = make_zoom_pair(raccoon, RATIO, np.random.default_rng(0), high_size=TINY, low_max=TINY)
    cv2.imwrite(str(folder / "low.png"), np.clip(pair.low, 0, 255).astype(np.uint8))
    cv2.imwrite(str(folder / "high.png"), np.clip(pair.high, 0, 255).astype(np.uint8))
    rng = np.random.default_rng(1)
    for name in ("noise_low.png", "noise_high.png"):
        noise = np.clip(128 + rng.normal(0, 3, TINY[::-1]), 0, 255).astype(np.uint8)
        cv2.imwrite(str(folder / name), noise)
    return folder


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def lines_of_text(text: str):
    return [json.loads(x) for x in text.splitlines()]


def lines_of(path: Path):
    return lines_of_text(path.read_text())


def keys_of(lines):
    return sorted((x["low"]["path"], x["high"]["path"]) for x in lines)


# --------------------------------------------------------------------------- the lines of a run

def test_counts_add_each_line_by_its_verdict():
    counts = Counts()
    for line in ({"matched": True}, {"matched": False}, {"matched": True},
                 {"matched": False, "error": "no such file", "error_kind": batch.INPUT},
                 {"matched": False, "error": "internal error: MemoryError",
                  "error_kind": batch.INTERNAL}):
        counts = counts.add(line)
    assert counts == Counts(matched=2, no_match=1, errors=2, internal=1)
    assert counts.lines == 5 and Counts().lines == 0


# --------------------------------------------------------------------------- bounded in-flight

def test_bounded_keeps_at_most_limit_in_flight_and_yields_each_pair_once():
    pairs = [Pair(str(k), str(k), "", "") for k in range(10)]
    pending, most, stopped = [], [0], []

    def submit(pair):
        future = concurrent.futures.Future()
        pending.append((future, pair))
        most[0] = max(most[0], len(pending))
        return future

    def wait_first(futures):  # finishes the oldest submitted
        future, pair = pending.pop(0)
        future.set_result({"low": {"path": pair.low}})
        return [future]

    lines = bounded(pairs, submit, wait_first, lambda fut, pair: fut.result(), limit=lambda: 3,
                    stop=stopped.extend)
    assert [x["low"]["path"] for x in lines] == [str(k) for k in range(10)]
    assert most[0] == 3 and stopped == []

    pending.clear()
    early = bounded(pairs, submit, wait_first, lambda fut, pair: fut.result(), limit=lambda: 3,
                    stop=stopped.extend)
    assert next(early)["low"]["path"] == "0"
    early.close()  # as on Ctrl-C: the unfinished futures are handed to stop
    assert len(stopped) == 2 and all(not f.done() for f in stopped)  # 3 in flight, 1 yielded


# --------------------------------------------------------------------------- the command

def test_batch_good_pair_no_match_and_missing_file_exit_3(images):
    pairs = write(images / "p1.csv", "low.png,high.png\nnoise_low.png,noise_high.png\n"
                                     "low.png,missing.png\n")
    result = run("batch", pairs, "-q")
    assert result.exit_code == 3, result.output
    good, bad, flat = sorted(lines_of_text(result.stdout), key=lambda x: x["high"]["path"])
    assert good["matched"] is True and JSON_KEYS <= set(good) and "error" not in good
    assert abs(good["resolution_ratio"] - RATIO) < 0.05 and good["low"]["path"] == "low.png"
    assert bad["matched"] is False and "missing.png" in bad["error"]
    assert bad["config"] == good["config"]  # error lines record the config too (for resume)
    assert flat["matched"] is False and flat["reason"] and "error" not in flat


def test_a_csv_s_other_columns_come_back_on_each_line(images):
    """A header CSV's other columns (an id, the ratio expected) ride on the pair's line, error
    lines included, so that a CI script compares without a join."""
    pairs = write(images / "p14.csv", f"name,low,high,expected\nfirst,low.png,high.png,{RATIO}\n"
                                      f"second,low.png,gone.png,{RATIO}\n")
    result = run("batch", pairs, "-q")
    bad, good = sorted(lines_of_text(result.stdout), key=lambda x: "error" not in x)
    assert good["csv"] == {"name": "first", "expected": str(RATIO)} and good["matched"] is True
    assert bad["csv"] == {"name": "second", "expected": str(RATIO)} and "error" in bad
    assert abs(good["resolution_ratio"] - float(good["csv"]["expected"])) < 0.05
    plain = run("batch", write(images / "p15.csv", "low.png,high.png\n"), "-q")
    assert "csv" not in lines_of_text(plain.stdout)[0]  # no header: nothing to carry


def test_batch_exit_0_when_no_pair_errored(images):
    pairs = write(images / "p2.csv", "low.png,high.png\nnoise_low.png,noise_high.png\n")
    assert run("batch", pairs, "-q").exit_code == 0


def test_exit_3_is_documented():
    text = run("batch", "--help").output
    assert "3 batch: some pair has an \"error\" line" in " ".join(text.split())


def test_a_paper_mode_batch_resumes(images, tmp_path):
    """A line's config is the options alone: what the search used (the covariance of the paper
    mode, ``covariance_used``) is in the result beside it, so a paper-mode batch run a second
    time resumes from its own file (not refused as "made with other options") and adds
    nothing."""
    out = tmp_path / "paper.jsonl"
    pairs = write(tmp_path / "pairs.csv", f"{images}/low.png,{images}/high.png\n")
    first = run("batch", pairs, "--mode", "paper", "--output", out, "-q")
    assert first.exit_code == 0, first.output
    line = json.loads(out.read_text())
    assert line["covariance_used"].startswith("packaged sha256:")
    assert "covariance_used" not in line["config"]
    again = run("batch", pairs, "--mode", "paper", "--output", out)
    assert again.exit_code == 0, again.output
    assert "resuming: 1 of 1" in again.stderr and out.read_text().count("\n") == 1


def test_batch_resume_skips_done_pairs_and_cuts_a_torn_line(images, tmp_path):
    out = tmp_path / "results.jsonl"
    pairs = write(tmp_path / "pairs.csv", f"{images}/low.png,{images}/high.png\n"
                                          f"{images}/high.png,{images}/low.png\n")
    assert run("batch", pairs, "--output", out, "-q").exit_code == 0
    first = out.read_text().splitlines()
    assert len(first) == 2
    # an interruption tore a third line; then the CSV grows by one pair
    with open(out, "a") as fh:
        fh.write('{"low": {"path": "x"}, "matc')
    write(pairs, pairs.read_text() + f"{images}/low.png,{tmp_path}/gone.png\n")
    result = run("batch", pairs, "--output", out)
    assert result.exit_code == 3, result.output
    lines = out.read_text().splitlines()
    assert lines[:2] == first  # done pairs are neither redone nor rewritten
    assert len(lines) == 3 and "gone.png" in json.loads(lines[2])["error"]
    assert "resuming: 2 of 3" in result.stderr
    # everything done: a third run adds nothing, and still says a pair errored
    again = run("batch", pairs, "--output", out)
    assert again.exit_code == 3 and out.read_text().splitlines() == lines
    assert "1 of them an error" in again.stderr


def test_retry_errors_matches_again_a_pair_whose_image_is_fixed(images, tmp_path):
    out, later = tmp_path / "r.jsonl", tmp_path / "later.png"  # later.png: missing at first
    # an error line of a pair another CSV gave: not this CSV's, so not retried, kept as it is
    elsewhere = write(tmp_path / "elsewhere.csv", f"{images}/low.png,{tmp_path}/gone.png\n")
    assert run("batch", elsewhere, "--output", out, "-q").exit_code == 3
    pairs = write(tmp_path / "pairs.csv", f"{images}/low.png,{images}/high.png\n"
                                          f"{images}/low.png,{later}\n"
                                          f"{images}/noise_low.png,{images}/noise_high.png\n")
    assert run("batch", pairs, "--output", out, "-q").exit_code == 3
    before = out.read_bytes().splitlines(keepends=True)
    assert len(before) == 4 and sum(b'"error"' in x for x in before) == 2
    shutil.copy(images / "high.png", later)  # the image is there now

    plain = run("batch", pairs, "--output", out)  # without the flag: the error line stays
    assert plain.exit_code == 3 and out.read_bytes() == b"".join(before)
    assert "(3 done before, 1 of them an error)" in plain.stderr

    with open(out, "ab") as fh:
        fh.write(b'{"low": {"path": "x"}, "matc')  # a line torn by an interruption
    os.chmod(out, 0o640)
    result = run("batch", pairs, "--output", out, "--retry-errors")
    assert result.exit_code == 0, result.output
    after = out.read_bytes().splitlines(keepends=True)
    assert after[:3] == [x for x in before if str(later).encode() not in x]  # byte for byte
    new = json.loads(after[3])
    assert len(after) == 4 and new["high"]["path"] == str(later) and new["matched"] is True
    assert abs(new["resolution_ratio"] - RATIO) < 0.05
    assert "resuming: 2 of 3" in result.stderr and "retrying 1 pair whose" in result.stderr
    assert "1 pair: 1 matched, 0 no reliable match, 0 errors (2 done before, 0 of them errors)" \
        in result.stderr
    assert stat.S_IMODE(out.stat().st_mode) == 0o640
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp file


def test_retry_errors_keeps_exit_3_while_a_pair_still_fails(images, tmp_path):
    out = tmp_path / "r.jsonl"
    pairs = write(tmp_path / "pairs.csv", f"{images}/low.png,{images}/high.png\n"
                                          f"{images}/low.png,{tmp_path}/gone.png\n")
    assert run("batch", pairs, "--output", out, "-q").exit_code == 3
    first = out.read_text().splitlines()
    result = run("batch", pairs, "--output", out, "--retry-errors")
    assert result.exit_code == 3, result.output
    lines = out.read_text().splitlines()
    good = [x for x in first if '"error"' not in x]
    assert len(lines) == 2 and lines[0] == good[0] and "gone.png" in json.loads(lines[1])["error"]
    assert "1 pair: 0 matched, 0 no reliable match, 1 error (1 done before, 0 of them errors)" \
        in result.stderr


def test_a_bad_set_stops_the_batch_before_any_pair_runs(images):
    pairs = write(images / "p13.csv", "low.png,high.png\n")
    result = run("batch", pairs, "--set", "ransac=1")
    assert_one_line_error(result, "'ransac' is a group of parameters")
    assert result.stdout == ""  # no line for any pair


@pytest.mark.parametrize("option", [["--seed", "9223372036854775808"],
                                    ["--set", "seed=2147483648"]])
def test_a_seed_out_of_range_stops_the_batch_before_any_pair_runs(images, tmp_path, option):
    """A seed OpenCV cannot take (a C int) wrote an error line for every pair into the
    resumable output; it is one usage error now, before the output is made."""
    pairs = write(images / "p13.csv", "low.png,high.png\n")
    out = tmp_path / "results.jsonl"
    result = run("batch", pairs, "--output", out, *option)
    assert_one_line_error(result, "seed")
    assert "2147483647" in result.stderr and not out.exists()


def test_a_constant_image_s_error_line_names_its_file(images):
    cv2.imwrite(str(images / "flat.png"), np.full((100, 120), 9, np.uint8))
    pairs = write(images / "p14.csv", "low.png,flat.png\n")
    result = run("batch", pairs, "-q")
    line = json.loads(result.stdout)
    assert result.exit_code == 3 and line["error_kind"] == "input"
    assert line["error"] == (f"{images / 'flat.png'}: image is constant (every pixel 9): "
                             f"there is nothing to match in it")


def test_an_image_given_as_the_csv_is_named_not_a_text_file(images):
    assert_one_line_error(run("batch", images / "low.png"), "is not a text file (an image?)")


def test_an_empty_csv_says_it_lists_no_pairs(images):
    result = run("batch", write(images / "empty.csv", ""))
    assert result.exit_code == 0 and "empty.csv lists no pairs" in result.stderr


def test_retry_errors_needs_an_output_file(images):
    pairs = write(images / "p12.csv", "low.png,high.png\n")
    assert_one_line_error(run("batch", pairs, "--retry-errors"), "give that file with --output")


@pytest.mark.parametrize("retry", [[], ["--retry-errors"]])
@pytest.mark.parametrize("content", ["my notes\nsecond line\n", "low,high\na.png,b.png\n"])
def test_output_holding_other_lines_is_refused_and_left_untouched(images, tmp_path, content,
                                                                 retry):
    pairs = write(tmp_path / "pairs.csv", f"{images}/low.png,{images}/high.png\n")
    notes = write(tmp_path / "notes.txt", content)
    assert_one_line_error(run("batch", pairs, "--output", notes, *retry),
                          "not a scalematch result")
    assert notes.read_text() == content


def test_output_is_the_pairs_csv_itself(images):
    pairs = write(images / "p3.csv", "low,high\nlow.png,high.png\n")
    assert_one_line_error(run("batch", pairs, "--output", pairs), "is an input")
    assert pairs.read_text() == "low,high\nlow.png,high.png\n"


def test_output_is_an_image_of_a_pair_by_another_name(images, tmp_path):
    """The same check as match's --json: an input under another spelling (or a hard link)."""
    pairs = write(images / "p3b.csv", "low.png,high.png\n")
    before = (images / "high.png").read_bytes()
    last = assert_one_line_error(run("batch", pairs, "--output", images / "." / "high.png"),
                                 "is an input")
    assert "overwritten" in last
    link = tmp_path / "linked.png"
    os.link(images / "high.png", link)
    assert_one_line_error(run("batch", pairs, "--output", link), "is an input")
    assert (images / "high.png").read_bytes() == before


def test_resume_with_other_options_is_refused_and_left_untouched(images, tmp_path):
    out = tmp_path / "r.jsonl"
    pairs = write(tmp_path / "pairs.csv", f"{images}/noise_low.png,{images}/noise_high.png\n")
    assert run("batch", pairs, "--output", out, "-q").exit_code == 0
    before = out.read_bytes()
    last = assert_one_line_error(run("batch", pairs, "--output", out, "--model", "affine"),
                                 "other options")
    assert "(made with no matching options; this run: --model affine)" in last
    assert_one_line_error(run("batch", pairs, "--output", out, "--ransac-threshold", "2"),
                          "this run: --ransac-threshold 2.0)")
    paper = assert_one_line_error(run("batch", pairs, "--output", out, "--mode", "paper"),
                                  "other options")
    assert "this run: --mode paper)" in paper and "min_points" not in paper
    assert out.read_bytes() == before
    assert run("batch", pairs, "--output", out, "-q").exit_code == 0  # same options: resumes
    assert out.read_bytes() == before


def test_repeated_rows_are_matched_once_and_resume_counts_right(images, tmp_path):
    row = f"{images}/low.png,{images}/high.png\n"
    other = f"{images}/noise_low.png,{images}/noise_high.png\n"
    pairs = write(tmp_path / "pairs.csv", row + row + other + row)
    out = tmp_path / "r.jsonl"
    # interrupted after the first pair: only its line is in the file
    result = run("batch", write(tmp_path / "first.csv", row), "--output", out, "-q")
    assert result.exit_code == 0
    result = run("batch", pairs, "--output", out)
    assert result.exit_code == 0, result.output
    assert "rows repeated in" in result.stderr and ": 2 (each pair is matched once)" in result.stderr
    assert "resuming: 1 of 2" in result.stderr
    assert keys_of(lines_of(out)) == sorted([(f"{images}/low.png", f"{images}/high.png"),
                                             (f"{images}/noise_low.png",
                                              f"{images}/noise_high.png")])


def test_named_columns_in_any_position(images):
    pairs = write(images / "p4.csv", "name,high,low\nraccoon,high.png,low.png\n")
    result = run("batch", pairs, "-q")
    assert result.exit_code == 0, result.output
    (line,) = lines_of_text(result.stdout)
    assert line["low"]["path"] == "low.png" and line["matched"] is True


def test_three_columns_without_header_are_refused(images):
    pairs = write(images / "p5.csv", "raccoon,low.png,high.png\n")
    assert_one_line_error(run("batch", pairs), "3 columns")


def test_batch_with_worker_processes(images):
    pairs = write(images / "p6.csv", "low.png,high.png\nnoise_low.png,noise_high.png\n"
                                     "p6.csv,high.png\n")
    result = run("batch", pairs, "--jobs", "2", "-q")
    assert result.exit_code == 3, result.output
    lines = sorted(lines_of_text(result.stdout), key=lambda x: x["low"]["path"])
    assert [x["low"]["path"] for x in lines] == ["low.png", "noise_low.png", "p6.csv"]
    assert lines[0]["matched"] is True and lines[1]["matched"] is False
    assert "error" not in lines[1] and "error" in lines[2]


def test_scheduler_without_dask_installed_is_a_clear_error(images, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed fails
    pairs = write(images / "p7.csv", "low.png,high.png\n")
    assert_one_line_error(run("batch", pairs, "--scheduler", "tcp://127.0.0.1:8786"),
                          "pip install 'scalematch[dask]'")


def test_scheduler_and_jobs_together_are_a_usage_error(images):
    pairs = write(images / "p8.csv", "low.png,high.png\n")
    assert_one_line_error(run("batch", pairs, "--scheduler", "tcp://127.0.0.1:8786", "-j", "2"),
                          "--jobs is for local processes")


# --------------------------------------------------------------------------- kill -9

def _children(pid: int):
    """Pids of the live (not zombie) processes whose parent is ``pid`` (Linux /proc)."""
    out = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            state, ppid = _stat(int(name))
            if ppid == pid and state != "Z":
                out.append(int(name))
    return out


def _stat(pid: int):
    """(state, parent pid) of ``pid``, or ("", -1) when it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return "", -1
    fields = text[text.rindex(")") + 2:].split()
    return fields[0], int(fields[1])


def _alive(pid: int) -> bool:
    return _stat(pid)[0] not in ("", "Z")


def _complete_lines(path: Path) -> int:
    try:
        return path.read_bytes().count(b"\n")
    except FileNotFoundError:
        return 0


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_kill_9_leaves_no_worker_alive_and_resume_loses_nothing(images, tmp_path):
    """Also: nothing on stderr after the kill, nor from the resumed run. The process pool of
    before made semaphores (its queues' locks) that multiprocessing's resource tracker, which
    outlives the main process, removed after kill -9 with "UserWarning: resource_tracker: There
    appear to be 5 leaked semaphore objects to clean up at shutdown"."""
    n = 24  # distinct pairs (hard links of the tiny pair): ~1 s of work for 2 workers
    for k in range(n):
        os.link(images / "low.png", tmp_path / f"l{k}.png")
        os.link(images / "high.png", tmp_path / f"h{k}.png")
    pairs = write(tmp_path / "pairs.csv", "".join(f"l{k}.png,h{k}.png\n" for k in range(n)))
    out = tmp_path / "r.jsonl"
    cmd = [sys.executable, "-m", "scalematch.cli", "batch", str(pairs), "--output", str(out),
           "--jobs", "2", "-q"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while _complete_lines(out) < 1 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.01)
        workers = _children(proc.pid)
        proc.send_signal(signal.SIGKILL)
        # stderr ends when the last process holding it (workers, resource tracker) has ended
        _, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    done_at_kill = _complete_lines(out)
    assert 1 <= done_at_kill < n, "the kill came too late to test anything"
    assert len(workers) >= 2, workers  # two workers (and multiprocessing's resource tracker)
    deadline = time.monotonic() + 10
    while any(_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not [w for w in workers if _alive(w)], "a worker outlived the main process"
    assert stderr == "", stderr  # no "leaked semaphore objects"

    resumed = subprocess.run(cmd[:-1], capture_output=True, text=True, timeout=120)
    assert resumed.returncode == 0, resumed.stderr
    assert "leaked" not in resumed.stderr and "Warning" not in resumed.stderr, resumed.stderr
    assert f"resuming: {done_at_kill} of {n}" in resumed.stderr
    lines = lines_of(out)  # every line whole (a torn one was cut)
    assert keys_of(lines) == sorted((f"l{k}.png", f"h{k}.png") for k in range(n))  # once each
    assert all(x["matched"] for x in lines)


def _workers(pid: int):
    """Pids of the pool workers among the children of ``pid`` (not the resource tracker)."""
    return [w for w in _children(pid)
            if b"spawn_main" in Path(f"/proc/{w}/cmdline").read_bytes()]


#: Runs ``scalematch`` with the arguments given, Ctrl-C raising KeyboardInterrupt even when the
#: tests run where SIGINT is ignored (a shell's background job inherits that).
CLI_WITH_CTRL_C = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
                   "from scalematch.cli import main; main(sys.argv[1:])")


def _start_batch(tmp_path: Path, images: Path, n: int):
    """(pairs CSV, output, the running ``scalematch batch --jobs 2`` of n distinct tiny pairs),
    once the first line is written."""
    for k in range(n):  # hard links: distinct pairs, no copies
        os.link(images / "low.png", tmp_path / f"l{k}.png")
        os.link(images / "high.png", tmp_path / f"h{k}.png")
    pairs = write(tmp_path / "pairs.csv", "".join(f"l{k}.png,h{k}.png\n" for k in range(n)))
    out = tmp_path / "r.jsonl"
    cmd = [sys.executable, "-c", CLI_WITH_CTRL_C, "batch", str(pairs), "--output", str(out),
           "--jobs", "2"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while _complete_lines(out) < 1 and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.01)
    return pairs, out, proc


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_worker_killed_mid_run_is_replaced_and_every_pair_matched(images, tmp_path):
    n = 24
    _, out, proc = _start_batch(tmp_path, images, n)
    try:
        workers = _workers(proc.pid)
        done_at_kill = _complete_lines(out)
        os.kill(workers[0], signal.SIGKILL)  # as the out-of-memory killer does
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert 1 <= done_at_kill < n, "the kill came too late to test anything"
    assert proc.returncode == 0, stderr
    lines = lines_of(out)
    assert keys_of(lines) == sorted((f"l{k}.png", f"h{k}.png") for k in range(n))  # once each
    assert not [x["error"] for x in lines if "error" in x] and all(x["matched"] for x in lines)
    assert f"{n} pairs: {n} matched, 0 no reliable match, 0 errors" in stderr


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_ctrl_c_exits_130_and_stops_the_workers_at_once(images, tmp_path):
    n = 24
    _, out, proc = _start_batch(tmp_path, images, n)
    try:
        workers = _workers(proc.pid)
        proc.send_signal(signal.SIGINT)
        _, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert len(workers) == 2, workers
    assert proc.returncode == 130, stderr
    assert _complete_lines(out) < n, "the batch ended before Ctrl-C"
    assert "interrupted:" in stderr and "run the same command again to resume" in stderr
    deadline = time.monotonic() + 5
    while any(_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not [w for w in workers if _alive(w)], "a worker outlived Ctrl-C"


# --------------------------------------------------------------------------- Dask

def _comparable(line):
    """A line without what changes from run to run (times)."""
    return {k: v for k, v in line.items() if k not in ("seconds", "timings")}


def test_dask_local_cluster_same_lines_resume_and_progress(images, tmp_path):
    distributed = pytest.importorskip("distributed")
    rows = ["low.png,high.png\n", "noise_low.png,noise_high.png\n", "low.png,missing.png\n"]
    local = run("batch", write(images / "p9.csv", "".join(rows)), "-q")
    assert local.exit_code == 3

    out = tmp_path / "r.jsonl"
    threads = cv2.getNumThreads()  # the threaded workers set OpenCV's (process-wide) threads
    try:
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                      protocol="tcp", host="127.0.0.1",
                                      dashboard_address=None) as cluster:
            address = cluster.scheduler_address
            assert address.startswith("tcp://127.0.0.1:")
            two = write(images / "p10.csv", "".join(rows[:2]))
            first = run("batch", two, "--output", out, "--scheduler", address, "-q")
            assert first.exit_code == 0, first.output
            assert len(lines_of(out)) == 2
            whole = write(images / "p11.csv", "".join(rows))
            second = run("batch", whole, "--output", out, "--scheduler", address)
    finally:
        cv2.setNumThreads(threads)
    assert second.exit_code == 3, second.output
    assert "resuming: 2 of 3" in second.stderr
    assert "1 pair: 0 matched, 0 no reliable match, 1 error" in second.stderr
    by_key = {(x["low"]["path"], x["high"]["path"]): _comparable(x) for x in lines_of(out)}
    expected = {(x["low"]["path"], x["high"]["path"]): _comparable(x)
                for x in lines_of_text(local.stdout)}
    assert by_key == expected  # the same JSON lines as the local run


# --------------------------------------------------------------------------- unexpected errors

def test_an_unexpected_error_is_an_internal_line_the_batch_goes_on_and_exits_4(images,
                                                                               monkeypatch):
    """A MemoryError in one pair (raised here: under a real memory limit, see test_cli.py's
    test_out_of_memory_exits_4_not_1) gives that pair an internal error line; the next pair is
    matched; the batch exits 4, not 3 (bad input) nor 1."""
    import scalematch.batch as batch_module

    real = batch_module.match
    calls = []

    def first_runs_out(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            raise MemoryError("Unable to allocate 1.00 GiB")
        return real(*args, **kwargs)

    monkeypatch.setattr(batch_module, "match", first_runs_out)
    pairs = write(images / "p_internal.csv", "noise_low.png,noise_high.png\nlow.png,missing.png\n"
                                             "low.png,high.png\n")
    result = run("batch", pairs)
    assert result.exit_code == 4, (result.exit_code, result.stderr)
    lines = lines_of_text(result.stdout)
    assert [x.get("error_kind") for x in lines] == ["internal", "input", None]
    assert lines[0]["error"] == "internal error, out of memory (MemoryError: Unable to allocate " \
                                "1.00 GiB)"
    assert lines[2]["matched"] is True
    assert "3 pairs: 1 matched, 0 no reliable match, 2 errors (1 internal)" in result.stderr


@pytest.mark.parametrize("address, needle", [
    ("notaurl", "no port"), ("127.0.0.1", "no port"), ("tcp://127.0.0.1", "no port"),
    ("http://127.0.0.1:8787", "dashboard"), ("foo://host:8786", "unknown scheme"),
    ("tcp://host:99999", "1-65535")])
def test_a_malformed_scheduler_address_fails_at_once(images, address, needle):
    pairs = write(images / "p_dask.csv", "low.png,high.png\n")
    last = assert_one_line_error(run("batch", pairs, "--scheduler", address), needle)
    assert "tcp://127.0.0.1:8786" in last  # the form, by example


#: Runs ``scalematch`` with the arguments given, where making a Dask client says so on stderr
#: and ends the process (exit 99): nothing may try to connect.
CLI_WITHOUT_CLIENTS = """
import sys
try:
    import distributed
except ImportError:
    pass
else:
    def client(*args, **kwargs):
        sys.stderr.write("a client was made\\n")
        raise SystemExit(99)
    distributed.Client = client
from scalematch.cli import main
main(sys.argv[1:])
"""


def test_a_malformed_scheduler_address_in_a_real_process_is_one_line(images):
    """In a process of its own (where distributed's Client.__del__ would print at exit): one
    line, exit 2, and at once: the address is refused from its form, before any client tries
    to connect (which would wait for the connection's time-out, 10 s)."""
    pairs = write(images / "p_dask.csv", "low.png,high.png\n")
    done = subprocess.run([sys.executable, "-c", CLI_WITHOUT_CLIENTS, "batch", str(pairs),
                           "--scheduler", "notaurl"], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "no port" in done.stderr and "a client was made" not in done.stderr, done.stderr
    assert "Exception ignored" not in done.stderr


def test_a_ctrl_c_worn_by_a_library_error_stops_the_batch(images, monkeypatch):
    # a lock released twice as Ctrl-C unwound a wait (threading's Condition): the error has
    # the interrupt as its context, and must not be taken for the pair's internal error
    def unwound(*args, **kwargs):
        try:
            raise KeyboardInterrupt
        finally:
            raise RuntimeError("release unlocked lock")

    monkeypatch.setattr(batch, "match", unwound)
    pair = Pair(str(images / "low.png"), str(images / "high.png"),
                str(images / "low.png"), str(images / "high.png"))
    with pytest.raises(KeyboardInterrupt):
        real_match_pair(pair, Config(), DEFAULT_MAX_PIXELS)


def test_the_help_examples_run_one_after_the_other_in_one_folder(tmp_path):
    """A user tries batch --help's examples in turn in one folder: none is refused (the second
    and third wrote one file with other options, exit 2), and each writes a line per pair."""
    import re
    import shlex

    root = Path(__file__).resolve().parents[1]
    row = f"{root}/data/demo_low.png,{root}/data/demo_high.png\n"
    for name in ("pairs.csv", "archive.csv"):
        write(tmp_path / name, row)
    help_text = run("batch", "--help").output
    examples = re.findall(r"^\s+(scalematch batch .*)$", help_text, re.M)
    assert len(examples) >= 4
    ran = 0
    for example in examples:
        if "--scheduler" in example:
            continue  # needs a Dask cluster
        words = shlex.split(example)
        target = words.index(">") if ">" in words else None
        args = words[1:target]
        args = [str(tmp_path / a) if a.endswith(".csv") else a for a in args]
        if "--output" in args:
            k = args.index("--output") + 1
            args[k] = str(tmp_path / args[k])
        result = run(*args, "-q")
        assert result.exit_code == 0, (example, result.output)
        if target is not None:
            write(tmp_path / words[target + 1], result.stdout)
        ran += 1
    assert ran == len(examples) - 1
    for name in ("results.jsonl", "paper.jsonl", "archive.jsonl"):
        lines = (tmp_path / name).read_text().splitlines()
        assert len(lines) == 1 and json.loads(lines[0])["matched"] is True, name


def _on_a_terminal(args, cwd: Path) -> str:
    """What ``scalematch ARGS`` shows on a terminal that is both its stdout and its stderr."""
    import pty

    master, slave = pty.openpty()
    try:
        proc = subprocess.Popen([sys.executable, "-m", "scalematch.cli", *map(str, args)],
                                stdout=slave, stderr=slave, stdin=subprocess.DEVNULL, cwd=cwd)
        os.close(slave)
        shown = b""
        while True:
            try:
                chunk = os.read(master, 4096)
            except OSError:  # the terminal closed: the process is done
                break
            if not chunk:
                break
            shown += chunk
        assert proc.wait(timeout=120) == 0, shown
    finally:
        os.close(master)
    return shown.decode(errors="replace")


def test_batch_lines_on_a_terminal_do_not_run_into_a_progress_bar(tmp_path):
    root = Path(__file__).resolve().parents[1]
    pairs = write(tmp_path / "pairs.csv",
                  f"{root}/data/demo_low.png,{root}/data/demo_high.png\n"
                  f"{root}/data/demo_high.png,{root}/data/demo_low.png\n")
    shown = _on_a_terminal(["batch", pairs], tmp_path)
    lines = [line.strip("\r") for line in shown.replace("\r\n", "\n").split("\n")]
    records = [line for line in lines if '"matched"' in line]
    assert len(records) == 2 and all(line.startswith("{") for line in records), shown
    assert "matching pairs" not in shown
    assert lines[-1] == "" and "2 pairs: 2 matched" in shown


def test_more_jobs_than_cores_run_one_worker_a_core_and_say_so_once(monkeypatch, tmp_path):
    started = []
    real_pool = batchpool.run_pool

    def pool(pairs, config, max_pixels, jobs, task=None):
        started.append(jobs)
        return real_pool(pairs, config, max_pixels, jobs, task)

    monkeypatch.setattr("scalematch.batchrun.available_cores", lambda: 2)
    monkeypatch.setattr(batchpool, "run_pool", pool)
    root = Path(__file__).resolve().parents[1]
    pairs = write(tmp_path / "pairs.csv",
                  f"{root}/data/demo_low.png,{root}/data/demo_high.png\n"
                  f"{root}/data/demo_high.png,{root}/data/demo_low.png\n"
                  f"{root}/data/demo_low.png,{root}/data/demo_low.png\n")
    result = run("batch", pairs, "--jobs", "64", "--output", tmp_path / "r.jsonl")
    assert result.exit_code == 0, result.output
    assert started == [2]
    notes = [line for line in result.stderr.splitlines() if "--jobs 64" in line]
    assert notes == ["--jobs 64: this machine has 2 cores, so 2 worker processes run"]
    assert len((tmp_path / "r.jsonl").read_text().splitlines()) == 3
