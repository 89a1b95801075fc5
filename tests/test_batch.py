"""Batch: the pairs CSV (columns, header, repeated rows), the output file (refused when it holds
anything but results, or results of other options; a torn line cut), bounded in-flight work,
exit codes (3 when a pair errored), worker processes that die with the main process (kill -9),
resume after it, and the Dask backend on a LocalCluster on loopback."""

from __future__ import annotations

import concurrent.futures
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from scalematch.batch import (NOTHING_DONE, BatchError, Pair, bounded, config_changes,
                              config_json, cut_torn_line, read_pairs, scan_output, unique_pairs)
from scalematch.config import Config
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


# --------------------------------------------------------------------------- the pairs CSV

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
    ("only-one-column\n", "1 columns"),
    ("name,low,other\nx,a.png,b.png\n", "no column named 'high'"),
    ("low_a,low_b,high\na.png,b.png,c.png\n", "several columns named 'low'"),
    ("low,high\na.png,\n", "line 2 does not have two paths"),
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
    with pytest.raises(BatchError, match='model "homography" \\(now "similarity"\\)'):
        scan_output(out, config_json(Config()))


def test_config_changes_names_every_difference_by_path():
    old = {"model": "affine", "ransac": {"threshold_px": 2.0, "max_iters": 10}, "gone": 1}
    new = {"model": "affine", "ransac": {"threshold_px": 3.0, "max_iters": 10}}
    assert config_changes(old, new) == ['gone 1 (now "absent")', "ransac.threshold_px 2.0 (now 3.0)"]


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


def test_batch_exit_0_when_no_pair_errored(images):
    pairs = write(images / "p2.csv", "low.png,high.png\nnoise_low.png,noise_high.png\n")
    assert run("batch", pairs, "-q").exit_code == 0


def test_exit_3_is_documented():
    text = run("batch", "--help").output
    assert "3 some pair" in " ".join(text.split())


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
    assert "1 of them errors" in again.stderr


@pytest.mark.parametrize("content", ["my notes\nsecond line\n", "low,high\na.png,b.png\n"])
def test_output_holding_other_lines_is_refused_and_left_untouched(images, tmp_path, content):
    pairs = write(tmp_path / "pairs.csv", f"{images}/low.png,{images}/high.png\n")
    notes = write(tmp_path / "notes.txt", content)
    assert_one_line_error(run("batch", pairs, "--output", notes), "not a scalematch result")
    assert notes.read_text() == content


def test_output_is_the_pairs_csv_itself(images):
    pairs = write(images / "p3.csv", "low,high\nlow.png,high.png\n")
    assert_one_line_error(run("batch", pairs, "--output", pairs), "not a scalematch result")
    assert pairs.read_text() == "low,high\nlow.png,high.png\n"


def test_resume_with_other_options_is_refused_and_left_untouched(images, tmp_path):
    out = tmp_path / "r.jsonl"
    pairs = write(tmp_path / "pairs.csv", f"{images}/noise_low.png,{images}/noise_high.png\n")
    assert run("batch", pairs, "--output", out, "-q").exit_code == 0
    before = out.read_bytes()
    last = assert_one_line_error(run("batch", pairs, "--output", out, "--model", "affine"),
                                 "other options")
    assert 'model "similarity" (now "affine")' in last
    assert_one_line_error(run("batch", pairs, "--output", out, "--ransac-threshold", "2"),
                          "ransac.threshold_px 3.0 (now 2.0)")
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
    return path.read_bytes().count(b"\n") if path.exists() else 0


def test_a_worker_whose_parent_is_gone_exits_at_once():
    # die_with_parent(pid) in a process whose parent is not pid: the parent died before the
    # worker got to ask, so the worker must end there and then
    code = "from scalematch.batch import die_with_parent; die_with_parent(-1); print('alive')"
    run_ = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert run_.returncode == 1 and "alive" not in run_.stdout


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_kill_9_leaves_no_worker_alive_and_resume_loses_nothing(images, tmp_path):
    n = 24  # distinct pairs (hard links of the tiny pair): ~1 s of work for 2 workers
    for k in range(n):
        os.link(images / "low.png", tmp_path / f"l{k}.png")
        os.link(images / "high.png", tmp_path / f"h{k}.png")
    pairs = write(tmp_path / "pairs.csv", "".join(f"l{k}.png,h{k}.png\n" for k in range(n)))
    out = tmp_path / "r.jsonl"
    cmd = [sys.executable, "-m", "scalematch.cli", "batch", str(pairs), "--output", str(out),
           "--jobs", "2", "-q"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while _complete_lines(out) < 1 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.01)
        workers = _children(proc.pid)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
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

    result = run("batch", pairs, "--output", out, "-j", "2")
    assert result.exit_code == 0, result.output
    assert f"resuming: {done_at_kill} of {n}" in result.stderr
    lines = lines_of(out)  # every line whole (a torn one was cut)
    assert keys_of(lines) == sorted((f"l{k}.png", f"h{k}.png") for k in range(n))  # once each
    assert all(x["matched"] for x in lines)


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
    assert "1 pairs: 0 matched, 0 no reliable match, 1 errors" in second.stderr
    by_key = {(x["low"]["path"], x["high"]["path"]): _comparable(x) for x in lines_of(out)}
    expected = {(x["low"]["path"], x["high"]["path"]): _comparable(x)
                for x in lines_of_text(local.stdout)}
    assert by_key == expected  # the same JSON lines as the local run
