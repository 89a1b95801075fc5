"""How the command line ends in a process of its own, as a shell script sees it: Ctrl-C sent to
the process group of a running batch exits 130 every time; an output pipe closed by its reader
(``| head``) exits 141 (128 + SIGPIPE) with nothing on stderr, never 1 (no reliable match).

The in-process tests (``CliRunner``) are in test_cli.py and test_batch.py; these need a real
process: the exit code of the interpreter, its threads, its stdout."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DEMO_LOW = ROOT / "data" / "demo_low.png"
DEMO_HIGH = ROOT / "data" / "demo_high.png"

#: The command line as ``scalematch`` runs it (``main``), with Ctrl-C raising KeyboardInterrupt
#: even where the tests run with SIGINT ignored (a shell's background job inherits that).
CLI_WITH_CTRL_C = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
                   "from scalematch.cli import main; main(sys.argv[1:])")
#: Tries of Ctrl-C. An exit through the interpreter's shutdown aborts (SIGABRT, exit 134) in about
#: 1 try of 6 to 8 on a 2-core machine, so 20 tries almost always catch it (4 runs of 4, measured).
CTRL_C_TRIES = 20
#: Distinct pairs of the batch Ctrl-C interrupts: far more than are done before the signal.
CTRL_C_PAIRS = 40
#: Waits after the first line before Ctrl-C, s: each try stops the next pair at another point of
#: its match (one demo pair takes 0.04-0.07 s of matching, measured).
CTRL_C_DELAYS_S = tuple(0.004 * k for k in range(CTRL_C_TRIES))
#: 128 + SIGPIPE: what a shell reports for a writer killed by its closed pipe.
EXIT_BROKEN_PIPE = 141


def _demo_pairs(folder: Path, n: int) -> Path:
    """A pairs CSV of ``n`` distinct pairs, each the demo pair (hard links: no copies)."""
    rows = []
    for k in range(n):
        low, high = folder / f"low{k}.png", folder / f"high{k}.png"
        os.link(DEMO_LOW, low)
        os.link(DEMO_HIGH, high)
        rows.append(f"{low.name},{high.name}\n")
    pairs = folder / "pairs.csv"
    pairs.write_text("".join(rows))
    return pairs


def _interrupted_batch(pairs: Path, delay_s: float) -> subprocess.CompletedProcess:
    """Run ``scalematch batch pairs``, send SIGINT to its process group ``delay_s`` after its
    first line, and wait for it to end; stdout is the lines after the first."""
    proc = subprocess.Popen([sys.executable, "-c", CLI_WITH_CTRL_C, "batch", str(pairs), "-q"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:
        proc.stdout.readline()
        time.sleep(delay_s)
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


@pytest.mark.skipif(not hasattr(os, "killpg"), reason="needs process groups")
def test_ctrl_c_to_a_batch_process_group_exits_130_every_time(tmp_path):
    """The pipeline's threads may be inside OpenCV when Ctrl-C stops the main thread; an exit
    through the interpreter's shutdown aborts (SIGABRT) when a thread comes back from OpenCV
    then (``cli.EXITS_AT_ONCE``). Each try stops the batch at another point of a pair's match."""
    pairs = _demo_pairs(tmp_path, CTRL_C_PAIRS)
    ends = []
    for delay in CTRL_C_DELAYS_S:
        done = _interrupted_batch(pairs, delay)
        assert done.stdout.count(b"\n") + 1 < CTRL_C_PAIRS, "the batch ended before Ctrl-C"
        ends.append((done.returncode, done.stderr.decode(errors="replace").strip()[-200:]))
    assert [code for code, _ in ends] == [130] * CTRL_C_TRIES, ends
    assert all(text.startswith("interrupted: ") for _, text in ends), ends


def _into_closed_pipe(*args: str) -> subprocess.CompletedProcess:
    """Run ``scalematch *args`` with its stdout a pipe whose reader has gone (as ``| head -c 0``
    once head has ended): its first write fails."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        return subprocess.run([sys.executable, "-m", "scalematch", *args], stdout=write_end,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write_end)


def test_json_into_a_closed_pipe_exits_141_quietly():
    done = _into_closed_pipe(str(DEMO_LOW), str(DEMO_HIGH), "--json", "-")
    assert done.returncode == EXIT_BROKEN_PIPE, done.stderr
    assert done.stderr == ""


def test_batch_into_a_closed_pipe_exits_141_quietly(tmp_path):
    pairs = _demo_pairs(tmp_path, 2)
    for jobs in ("1", "2"):
        done = _into_closed_pipe("batch", str(pairs), "-q", "--jobs", jobs)
        assert done.returncode == EXIT_BROKEN_PIPE, (jobs, done.stderr)
        assert done.stderr == "", jobs


def test_help_into_a_closed_pipe_exits_141_quietly():
    for args in (["--help"], ["batch", "--help"]):
        done = _into_closed_pipe(*args)
        assert done.returncode == EXIT_BROKEN_PIPE and done.stderr == "", (args, done.stderr)


@pytest.mark.skipif(shutil.which("bash") is None, reason="needs bash")
def test_batch_piped_to_head_ends_0_or_141(tmp_path):
    """``scalematch batch p.csv | head -1``: 141 when head has gone before the batch writes
    again, 0 when the batch wrote everything first; never 1, nothing on stderr but the summary."""
    pairs = _demo_pairs(tmp_path, 3)
    script = f'set -o pipefail; "{sys.executable}" -m scalematch batch "{pairs}" | head -1'
    done = subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode in (0, EXIT_BROKEN_PIPE), done.stderr
    assert done.stdout.count("\n") == 1
    assert "Traceback" not in done.stderr and "Error" not in done.stderr, done.stderr
