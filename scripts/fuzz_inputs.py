"""How the reader fares on hostile image files: the slowest file and the peak memory.

Usage: python scripts/fuzz_inputs.py [--seed 0] [--per-kind 10] [--cli] [--cv2] [--keep DIR]

Writes the seeded fuzz corpus of ``scalematch.lab.fuzz`` (the demo image in PNG, JPEG, TIFF,
BMP and WebP, each mutated by byte flips, header flips, truncation, repeated chunks and huge
size fields: 250 files by default) and reads each file in a process of its own, as the command
line reads it (``scalematch.working.read_pair``'s reader, ``imageio.read_reduced``). For each
it measures the reading's wall time and the process's peak memory above what it held before
the reading and above the decoded image (``ru_maxrss`` of the child, from ``os.wait4``).

Prints the outcomes (read, refused), the slowest files and the largest memory; exits 1 when a
file took more than ``--max-seconds`` (2 s) or more than ``--max-mb`` (300 MB) above its
decoded image, or when the reader raised anything but ``ImageError``.

``--cli`` also runs ``scalematch FILE data/demo_high.png --no-views -q`` on every file and
counts its exit codes (0, 1 or 2 expected; 4 is a bug). ``--cv2`` measures ``cv2.imread``
alone on every file: what the decoder does without the reader's checks.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scalematch.lab.fuzz import PER_KIND, write_corpus  # noqa: E402

#: The child: peak memory before reading, then the reading, as JSON on stdout.
READ = """
import json, resource, sys, time
from scalematch.imagefile import ImageError
from scalematch.imageio import read_reduced
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
try:
    image = read_reduced(sys.argv[1], 2048).image
    outcome, nbytes = "read", image.nbytes
except ImageError as exc:
    outcome, nbytes = "refused: " + str(exc).split(": ", 1)[-1][:60], 0
except BaseException as exc:
    outcome, nbytes = f"RAISED {type(exc).__name__}: {exc}"[:120], 0
print(json.dumps({"seconds": time.perf_counter() - t0, "before_kb": before,
                  "outcome": outcome, "nbytes": nbytes}))
"""
CV2 = """
import json, resource, sys, time
import cv2
cv2.utils.logging.setLogLevel(0)
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
image = cv2.imread(sys.argv[1], cv2.IMREAD_UNCHANGED)
print(json.dumps({"seconds": time.perf_counter() - t0, "before_kb": before,
                  "outcome": "read" if image is not None else "refused",
                  "nbytes": image.nbytes if image is not None else 0}))
"""


def child(code: str, path: Path, timeout: float = 120.0) -> dict:
    """Run ``code`` on ``path`` in a process of its own: its JSON line, with ``peak_kb``."""
    proc = subprocess.Popen([sys.executable, "-c", code, str(path)], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    t0 = time.monotonic()
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        if time.monotonic() - t0 > timeout:
            proc.kill()
            pid, status, usage = os.wait4(proc.pid, 0)
            return {"seconds": timeout, "outcome": "TIMEOUT", "nbytes": 0, "before_kb": 0,
                    "peak_kb": usage.ru_maxrss}
        time.sleep(0.01)
    out = proc.stdout.read().strip().splitlines()
    proc.stdout.close()
    row = json.loads(out[-1]) if out else {"seconds": time.monotonic() - t0, "before_kb": 0,
                                           "nbytes": 0,
                                           "outcome": f"DIED {os.waitstatus_to_exitcode(status)}"}
    row["peak_kb"] = usage.ru_maxrss
    return row


def above_mb(row: dict) -> float:
    """Peak memory of the reading above what the process held before it and above the decoded
    image, MB."""
    return (row["peak_kb"] - row["before_kb"]) / 1024 - row["nbytes"] / 2**20


def report(name: str, rows: dict, top: int) -> list:
    print(f"\n{name}: {len(rows)} files")
    kinds = Counter(r["outcome"].split(":")[0] for r in rows.values())
    print("outcomes:", ", ".join(f"{k} {n}" for k, n in kinds.most_common()))
    slow = sorted(rows.items(), key=lambda kv: -kv[1]["seconds"])[:top]
    print("slowest:")
    for path, r in slow:
        print(f"  {r['seconds']:7.3f} s  {above_mb(r):7.1f} MB  {path.name}  {r['outcome']}")
    big = sorted(rows.items(), key=lambda kv: -above_mb(kv[1]))[:top]
    print("most memory above the decoded image:")
    for path, r in big:
        print(f"  {above_mb(r):7.1f} MB  {r['seconds']:7.3f} s  {path.name}  {r['outcome']}")
    return [slow[0], big[0]]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--per-kind", type=int, default=PER_KIND)
    ap.add_argument("--cli", action="store_true", help="also run the command line on each file")
    ap.add_argument("--cv2", action="store_true", help="also measure cv2.imread alone")
    ap.add_argument("--keep", type=Path, help="write the corpus here and keep it")
    ap.add_argument("--top", type=int, default=5)
    ap.add_argument("--max-seconds", type=float, default=2.0)
    ap.add_argument("--max-mb", type=float, default=300.0)
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        paths = write_corpus(folder, args.seed, args.per_kind)
        print(f"corpus: {len(paths)} files (seed {args.seed}) in {folder}")
        rows = {p: child(READ, p) for p in paths}
        (slow_path, slow), (big_path, big) = report("scalematch's reader", rows, args.top)
        failed = [p.name for p, r in rows.items() if not r["outcome"].startswith(
            ("read", "refused"))]
        over = slow["seconds"] > args.max_seconds or above_mb(big) > args.max_mb
        print(f"\nslowest file: {slow_path.name}, {slow['seconds']:.3f} s (limit "
              f"{args.max_seconds:g} s); most memory above its decoded image: {big_path.name}, "
              f"{above_mb(big):.1f} MB (limit {args.max_mb:g} MB)")
        if failed:
            print("not ImageError:", ", ".join(failed))
        if args.cv2:
            report("cv2.imread alone", {p: child(CV2, p) for p in paths}, args.top)
        if args.cli:
            high = ROOT / "data" / "demo_high.png"
            codes = Counter()
            for p in paths:
                run = subprocess.run([sys.executable, "-m", "scalematch", str(p), str(high),
                                      "--no-views", "-q"], capture_output=True, text=True)
                codes[run.returncode] += 1
                if run.returncode not in (0, 1, 2):
                    failed.append(p.name)
                    print(f"  {p.name}: exit {run.returncode}: {run.stderr.strip()[-200:]}")
            print("\ncommand line exit codes:", dict(sorted(codes.items())))
    return 1 if failed or over else 0


if __name__ == "__main__":
    sys.exit(main())
