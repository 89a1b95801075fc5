"""imagefile: what is not an image file to read whole (a device, a named pipe, a 1 GB file) is
refused before it is read, in a process whose memory could not hold it."""

from __future__ import annotations

from pathlib import Path

import cv2
import pytest

from test_imageio import write


#: Address space a command gets in the tests below: enough for Python, numpy and OpenCV (360 MB
#: of address space at start, measured) and for a batch process that has matched a small pair
#: (680 MB after one: the matcher's threads reserve malloc arenas; 700 MB failed in CI when
#: Pillow was then imported), below any whole read of the 1 GB file (with the 360 MB it would
#: need 1.4 GB), so reading it would fail with exit 4, not the exit 2 and message asserted.
#: A refused input takes about 60 MB of memory (RSS, measured).
LIMIT_AS_BYTES = 1000 << 20


#: Each command must be done by then (a read of /dev/urandom or a pipe would never end).
HOSTILE_TIMEOUT_S = 20


def hostile_cases(folder: Path):
    """(name, path, words of the expected message) for inputs that are not image files to read
    whole: a device of endless zeros, one of endless random bytes, a named pipe no one writes
    to, a 1 GB sparse file of zeros, and 1 GB of zeros after a PNG or a JPEG signature."""
    import os

    yield "dev-zero", Path("/dev/zero"), "is a device"
    yield "dev-urandom", Path("/dev/urandom"), "is a device"
    fifo = folder / "pipe.png"
    if not fifo.exists():
        os.mkfifo(fifo)
    yield "fifo", fifo, "is a named pipe"
    for name, head in (("sparse.bin", b""), ("sparse-png.png", b"\x89PNG\r\n\x1a\n"),
                       ("sparse-jpg.jpg", b"\xff\xd8\xff\xe0")):
        big = folder / name
        with open(big, "wb") as fh:
            fh.write(head)
            fh.truncate(1 << 30)
        yield name, big, "not an image" if not head else "cannot decode"
    yield "sparse-small-limit", big, "larger than an image within the limit"


def run_limited(args, timeout: float = HOSTILE_TIMEOUT_S):
    """The command line in a subprocess with its address space limited (``resource.setrlimit``
    in the child, not on the machine)."""
    import resource
    import subprocess
    import sys

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (LIMIT_AS_BYTES, LIMIT_AS_BYTES))

    return subprocess.run([sys.executable, "-m", "scalematch.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, preexec_fn=limit)


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="needs /dev/zero and named pipes")
def test_hostile_paths_are_refused_before_they_are_read(tmp_path, bgr):
    """As match inputs: exit 2, one line naming what the path is, in a subprocess whose memory
    could not hold a whole read; as batch rows: an error line each, the good pair still matched."""
    good = write(tmp_path / "good.png", cv2.imencode(".png", bgr)[1].tobytes())
    rows = []
    for name, path, needle in hostile_cases(tmp_path):
        extra = ["--max-pixels", "1000000"] if name == "sparse-small-limit" else []
        run = run_limited([path, good, "-q", *extra])
        lines = run.stderr.strip().splitlines()
        assert run.returncode == 2, (name, run.returncode, run.stderr)
        assert len(lines) == 1 and lines[0].startswith(f"Error: {path}: "), (name, run.stderr)
        assert needle in lines[0], (name, lines[0])
        if name != "sparse-small-limit":
            rows.append(f"{path},{good}\n")
    rows.insert(2, f"{good},{good}\n")
    pairs = write(tmp_path / "pairs.csv", "".join(rows).encode())
    run = run_limited(["batch", pairs, "-q"])
    assert run.returncode == 3, (run.returncode, run.stderr)  # some pair errored; none internal
    import json

    lines = [json.loads(s) for s in run.stdout.splitlines()]
    assert len(lines) == len(rows)
    errors = [x for x in lines if "error" in x]
    assert len(errors) == len(rows) - 1
    assert all(x["error_kind"] == "input" for x in errors)
    assert {x["low"]["path"] for x in errors} == {r.split(",")[0] for r in rows} - {str(good)}
