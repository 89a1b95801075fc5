"""batchpool: a worker killed mid-pair (its pair tried again, then given up with a resumable
error line), a worker replaced after an internal error (out of memory), the pairs after an
out-of-memory in the main process handed to a fresh one, a worker whose parent is gone."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from scalematch import batch, batchpool
from scalematch.batch import match_pair as real_match_pair  # the worker's own
from scalematch.batch import Pair
from scalematch.batchcsv import unique_pairs
from scalematch.batchpool import after_worker_death
from scalematch.batchresume import config_json, scan_output
from scalematch.config import Config
from scalematch.imagefile import DEFAULT_MAX_PIXELS
from scalematch.result import dumps

import test_batch
from test_batch import lines_of_text, write
from test_batchcsv import read_pairs
from test_cli import run

#: test_batch's fixture: a folder with a tiny zoom pair (low.png, high.png) and a noise pair
images = test_batch.images


def test_after_worker_death_tries_again_then_writes_a_resumable_error_line(tmp_path):
    pair = Pair("a.png", "b.png", "/data/a.png", "/data/b.png")
    assert after_worker_death(pair, 1, Config()) is None  # maybe another pair's doing: again
    line = after_worker_death(pair, 2, Config())
    assert line["matched"] is False and (line["low"]["path"], line["high"]["path"]) == pair.key
    assert "worker process died while matching it, 2 times" in line["error"]
    assert "out of memory" in line["error"]
    assert after_worker_death(pair, 2, Config(), max_deaths=3) is None
    # the line is a batch error line: a resumed batch counts it, --retry-errors retries it
    out = write(tmp_path / "r.jsonl", dumps(line) + "\n")
    assert scan_output(out, config_json(Config())).errors == {pair.key}


#: Set in a worker process once a pair ran it out of memory: every later pair there fails too,
#: as when the memory a MemoryError left taken is not given back (seen under RLIMIT_AS).
_OUT_OF_MEMORY = False


def _log(pair: Pair, what: str) -> None:
    """A line "low-name what" appended to log.txt beside the pair's low image (one write of a
    few bytes with O_APPEND: whole lines however many workers write)."""
    low = Path(pair.low_file)
    with open(low.parent / "log.txt", "a") as fh:
        fh.write(f"{low.name} {what}\n")


def match_or_fail(pair: Pair, config: Config, max_pixels: int):
    """``match_pair`` as a worker runs it, but the pair whose low image is named oom*.png raises
    MemoryError in ``match`` and leaves its process out of memory (every later match there
    raises too), and the pair whose low image is named exit1*.png ends its process with exit
    code 1, as OpenBLAS does from native code when it cannot allocate its buffers. Picklable by
    reference: ``run_pool`` hands it to worker processes, which import this module."""
    global _OUT_OF_MEMORY

    def match(low, high, cfg, **kwargs):
        global _OUT_OF_MEMORY
        if _OUT_OF_MEMORY or Path(pair.low).name.startswith("oom"):
            _OUT_OF_MEMORY = True
            raise MemoryError("Unable to allocate 1.00 GiB")
        return real_match(low, high, cfg, **kwargs)

    _log(pair, "start")
    if Path(pair.low).name.startswith("exit1"):
        _log(pair, "exits")
        os._exit(1)
    real_match = batch.match
    batch.match = match
    try:
        return real_match_pair(pair, config, max_pixels)
    finally:
        batch.match = real_match
        _log(pair, "end")


def _linked_pairs(images: Path, folder: Path, names) -> Path:
    """A pairs CSV in ``folder`` of the tiny pair under the low names ``names`` (hard links)."""
    folder.mkdir(exist_ok=True)
    for name in names:
        os.link(images / "low.png", folder / name)
    return write(folder / "pairs.csv", "".join(f"{name},{images / 'high.png'}\n"
                                               for name in names))


def test_a_worker_out_of_memory_is_replaced_before_it_takes_another_pair(images, tmp_path):
    """One pair's MemoryError in a worker process is that pair's internal error line; the worker
    ends and a fresh process takes the next pair, so the pairs after it are matched. One worker,
    so that with the pool of before (the same process takes the next pair) every later pair
    would fail."""
    names = ["oom.png"] + [f"l{k}.png" for k in range(3)]
    pairs = unique_pairs(read_pairs(_linked_pairs(images, tmp_path / "oom", names)),
                         tmp_path / "oom")
    lines = list(batchpool.run_pool(pairs, Config(), DEFAULT_MAX_PIXELS, 1, task=match_or_fail))
    assert [x["low"]["path"] for x in lines] == names  # one line each, in turn
    assert lines[0]["error_kind"] == "internal"
    assert lines[0]["error"] == ("internal error, out of memory (MemoryError: Unable to allocate "
                                 "1.00 GiB)")
    assert all(x["matched"] and "error" not in x for x in lines[1:])


def test_without_workers_the_pairs_after_an_out_of_memory_go_to_a_fresh_process(images, tmp_path,
                                                                               monkeypatch):
    """--jobs 1 matches in the main process; after one pair's MemoryError there the pairs left
    go to a worker process (this one may not have its memory back): they are matched."""
    names = ["oom.png"] + [f"l{k}.png" for k in range(3)]
    pairs = _linked_pairs(images, tmp_path / "serial", names)
    monkeypatch.setattr(batchpool, "match_pair", match_or_fail)
    monkeypatch.setattr(sys.modules[__name__], "_OUT_OF_MEMORY", False)  # this process's
    result = run("batch", pairs)
    assert result.exit_code == 4, (result.exit_code, result.stderr)
    lines = lines_of_text(result.stdout)
    assert [x["low"]["path"] for x in lines] == names
    assert lines[0]["error_kind"] == "internal"
    assert all(x["matched"] and "error" not in x for x in lines[1:])


def test_a_worker_that_exits_1_is_an_internal_error_never_no_match(images, tmp_path, monkeypatch):
    """A worker ending with exit code 1 (OpenBLAS out of memory, from native code) is a death:
    its pair is tried again alone, nothing beside it, then gets an internal error line naming
    the exit code; the other pairs are matched; the batch exits 4, not 1 nor 3."""
    names = ["l0.png", "exit1.png"] + [f"l{k}.png" for k in range(1, 5)]
    folder = tmp_path / "exit1"
    pairs = _linked_pairs(images, folder, names)
    monkeypatch.setattr(batchpool, "match_pair", match_or_fail)
    result = run("batch", pairs, "-j", "2")
    assert result.exit_code == 4, (result.exit_code, result.stderr)
    lines = {x["low"]["path"]: x for x in lines_of_text(result.stdout)}
    assert sorted(lines) == sorted(names)
    assert lines["exit1.png"]["error_kind"] == "internal" and not lines["exit1.png"]["matched"]
    assert ("its worker process died while matching it, 2 times, the last one exit code 1"
            in lines["exit1.png"]["error"])
    assert all(lines[n]["matched"] for n in names if n != "exit1.png")
    # the second try ran alone: every other pair started had ended, none started beside it
    log = (folder / "log.txt").read_text().splitlines()
    second = [i for i, x in enumerate(log) if x == "exit1.png start"][1]
    assert log[second + 1] == "exit1.png exits"
    before = [x for x in log[:second] if not x.startswith("exit1.png")]
    assert sum(x.endswith(" start") for x in before) == sum(x.endswith(" end") for x in before)


def test_a_worker_whose_parent_is_gone_exits_at_once():
    # die_with_parent(pid) in a process whose parent is not pid: the parent died before the
    # worker got to ask, so the worker must end there and then
    code = "from scalematch.batchpool import die_with_parent; die_with_parent(-1); print('alive')"
    run_ = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert run_.returncode == 1 and "alive" not in run_.stdout
