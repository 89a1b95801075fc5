"""How long a user waits: ``scalematch LOW HIGH`` against the SIFT reference.

Usage: python scripts/speed_bench.py [--photos N] [--ratios 2,3,4,6,8,10]
       [--parts process,inprocess,large]

The figures are in docs/design/SPEED.md.

A benchmark, not a test: nothing here asserts a time. On synthetic zoom pairs
(``scalematch.lab.synthetic.pairs_from_photos`` over ``../shared/data/photos``, EVALUATION.md),
written as 8-bit PNG files, it measures alternately in one run (scalematch, SIFT, SIFT,
scalematch, ... so that a change of machine load falls on both):

* the whole process: ``scalematch LOW HIGH`` against ``python scripts/sift_reference.py LOW
  HIGH`` (OpenCV SIFT, ratio test 0.8, ``cv2.estimateAffinePartial2D`` RANSAC 3 px), each a
  fresh subprocess reading the PNG files, what a shell script pays per pair;
* in one process: ``scalematch.match`` against ``scalematch.lab.baselines.match_baseline``
  (the same SIFT recipe) on the decoded images, with the success rate of each (error < 3 px);
* a 6000x4000 high image against a ~2 MP low image: wall time and peak resident memory of the
  whole ``scalematch LOW HIGH`` process (``os.wait4`` of the child).

Medians and the median of the per-pair ratios are printed as a Markdown table, with the load
average (``os.getloadavg``) before and after: on a shared machine the figures are noisy.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Sequence, Tuple

# one BLAS thread, as the command line uses: read when numpy loads, so set before the imports
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import cv2
import numpy as np

import scalematch
from scalematch.lab.baselines import match_baseline
from scalematch.lab.evaluation import is_success, reprojection_error
from scalematch.lab.synthetic import pairs_from_photos, zoom_pair_from_crop

ROOT = Path(__file__).resolve().parents[1]
SIFT_CMD = [sys.executable, str(ROOT / "scripts" / "sift_reference.py")]
#: The large pair: a 6000x4000 high image cut from the photo enlarged to 9000x6000, seen in a
#: low image of at most 1800x1200 px (2.2 MP) zoomed out by 5 (footprint about 1200x800 px).
LARGE_HIGH = (6000, 4000)
LARGE_SCENE = (9000, 6000)
LARGE_RATIO = 5.0
LARGE_LOW_MAX = (1800, 1200)


def write_png(path: Path, image: np.ndarray) -> str:
    cv2.imwrite(str(path), np.clip(np.rint(image), 0, 255).astype(np.uint8))
    return str(path)


#: Runs one command and reports (wall seconds, peak resident KB, exit code) of it alone: the
#: child is started from this small process, because Linux counts in a child's peak the
#: memory of the process it was forked from (this benchmark holds every pair in memory).
_TIMER = """
import os, subprocess, sys, time
t0 = time.perf_counter()
proc = subprocess.Popen(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
_, status, usage = os.wait4(proc.pid, 0)
print(time.perf_counter() - t0, usage.ru_maxrss, os.waitstatus_to_exitcode(status))
"""


def run_child(cmd: Sequence[str]) -> Tuple[float, float, int]:
    """(wall seconds, peak resident MB, exit code) of one child process."""
    out = subprocess.run([sys.executable, "-c", _TIMER, *cmd], capture_output=True, text=True,
                         check=True).stdout.split()
    return float(out[0]), int(out[1]) / 1024.0, int(out[2])


def load() -> str:
    return "/".join(f"{v:.1f}" for v in os.getloadavg())


def enlarged_scene(photo: Path) -> np.ndarray:
    """The photo, grey, enlarged (bicubic) to LARGE_SCENE px: the scene of the large pairs."""
    grey = cv2.imread(str(photo), cv2.IMREAD_GRAYSCALE).astype(np.float32)
    return cv2.resize(grey, LARGE_SCENE, interpolation=cv2.INTER_CUBIC)


def large_pair(scene: np.ndarray, seed: int, ratio: float = LARGE_RATIO,
               low_max: Tuple[int, int] = LARGE_LOW_MAX, source: str = ""):
    """The scene's centre LARGE_HIGH window as the high image, the scene zoomed out by ``ratio``
    in a window of at most ``low_max`` as the low one (the first seeded draw whose footprint
    fits the window)."""
    w, h = LARGE_HIGH
    x0, y0 = (scene.shape[1] - w) // 2, (scene.shape[0] - h) // 2
    for k in range(100):
        try:
            return zoom_pair_from_crop(scene, (x0, y0, w, h), ratio,
                                       np.random.default_rng([seed, 12, k]), low_max,
                                       source=source)
        except ValueError:
            continue
    raise RuntimeError("no angle fits the large pair's window")


def time_processes(files, scalematch_cmd: str) -> str:
    """Whole processes, alternately: one table row."""
    sm_t, sift_t = [], []
    for k, (lo, hi) in enumerate(files):
        got = {}
        for which in ("sm", "sift") if k % 2 == 0 else ("sift", "sm"):
            cmd = [scalematch_cmd, lo, hi] if which == "sm" else SIFT_CMD + [lo, hi]
            got[which] = run_child(cmd)[0]
        sm_t.append(got["sm"])
        sift_t.append(got["sift"])
    return _row("whole process", sm_t, sift_t)


def time_in_process(pairs) -> Tuple[str, str]:
    """``scalematch.match`` and the SIFT baseline in this process, alternately: (row, success)."""
    methods = {"sm": lambda p: (lambda r: r.transform if r.matched else None)(
                   scalematch.match(p.low, p.high)),
               "sift": lambda p: match_baseline(p.low, p.high, "sift").transform}
    times = {m: [] for m in methods}
    ok = {m: 0 for m in methods}
    for fn in methods.values():  # warm-up: one-off library set-up
        fn(pairs[0])
    for k, p in enumerate(pairs):
        for m in ("sm", "sift") if k % 2 == 0 else ("sift", "sm"):
            t0 = time.perf_counter()
            t = methods[m](p)
            times[m].append(time.perf_counter() - t0)
            ok[m] += is_success(reprojection_error(t, p.truth, p.high.shape, p.low.shape))
    n = len(pairs)
    return (_row("in process", times["sm"], times["sift"]),
            f"success (error < 3 px): scalematch {ok['sm']}/{n}, SIFT {ok['sift']}/{n}")


def time_large(photo: Path, seed: int, folder: Path, scalematch_cmd: str) -> str:
    """The 6000x4000 / ~2 MP pair, whole processes, two rounds: a Markdown table."""
    pair = large_pair(enlarged_scene(photo), seed, source=photo.name)
    lo = write_png(folder / "large_low.png", pair.low)
    hi = write_png(folder / "large_high.png", pair.high)
    h, w = pair.low.shape
    del pair
    lines = [f"6000x4000 high ({photo.name} enlarged), low {w}x{h}, ratio {LARGE_RATIO:g}, "
             "whole process (two rounds):\n",
             "| method | seconds | peak MB | exit | load 1/5/15 min |", "|---|---|---|---|---|"]
    for _ in range(2):
        for name, cmd in (("scalematch", [scalematch_cmd, lo, hi]), ("SIFT", SIFT_CMD + [lo, hi])):
            seconds, mb, code = run_child(cmd)
            lines.append(f"| {name} | {seconds:.2f} | {mb:.0f} | {code} | {load()} |")
    return "\n".join(lines)


def _row(name: str, sm_t: Sequence[float], sift_t: Sequence[float]) -> str:
    ratio = statistics.median(a / b for a, b in zip(sm_t, sift_t))
    return (f"| {name} | {statistics.median(sm_t):.3f} | {statistics.median(sift_t):.3f} | "
            f"{ratio:.2f} | {load()} |")


def main(argv: Sequence[str] = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared")
    ap.add_argument("--photos", type=int, default=0,
                    help="N photos spread evenly over the sorted list; 0 = all")
    ap.add_argument("--ratios", default="2,3,4,6,8,10")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--parts", default="process,inprocess,large",
                    help="what to measure: process (whole processes), inprocess, large")
    ap.add_argument("--scalematch", default=str(Path(sys.executable).with_name("scalematch")),
                    help="the scalematch command (default: next to this Python)")
    args = ap.parse_args(argv)
    parts = set(args.parts.split(","))
    every = sorted(p for p in (args.shared / "data" / "photos").iterdir()
                   if p.suffix.lower() in (".jpg", ".jpeg", ".png"))
    photos = every
    if 0 < args.photos < len(every):
        photos = [every[int(i)] for i in np.linspace(0, len(every) - 1, args.photos)]
    tmp = Path(tempfile.mkdtemp(prefix="speed-bench-"))
    print(f"load average before {load()}", file=sys.stderr)
    out = []
    if parts & {"process", "inprocess"}:
        pairs = list(pairs_from_photos(photos, [float(r) for r in args.ratios.split(",")],
                                       args.seed))
        out.append(f"{len(pairs)} pairs from {len(photos)} photos, ratios {args.ratios}, seed "
                   f"{args.seed}\n\n| timing | scalematch median s | SIFT median s | "
                   "median ratio | load 1/5/15 min after |\n|---|---|---|---|---|")
        if "process" in parts:
            files = [(write_png(tmp / f"{k}_low.png", p.low),
                      write_png(tmp / f"{k}_high.png", p.high)) for k, p in enumerate(pairs)]
            out.append(time_processes(files, args.scalematch))
        if "inprocess" in parts:
            row, success = time_in_process(pairs)
            out += [row, "\n" + success]
        del pairs
    if "large" in parts:  # the largest photo file of the folder, whatever --photos says
        out.append("\n" + time_large(max(every, key=lambda p: p.stat().st_size), args.seed, tmp,
                                      args.scalematch))
    print("\n".join(out))


if __name__ == "__main__":
    main()
