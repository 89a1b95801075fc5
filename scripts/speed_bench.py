"""How long a user waits: ``scalematch LOW HIGH`` against the SIFT reference (issue 12).

Usage: python scripts/speed_bench.py [--photos N] [--ratios 2,3,4,6,8,10] [--no-large]

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
from typing import List, Sequence, Tuple

import scalematch  # first: sets the BLAS threads before numpy loads
import cv2
import numpy as np

from scalematch.lab.baselines import match_baseline
from scalematch.lab.evaluation import is_success, reprojection_error
from scalematch.lab.synthetic import pairs_from_photos, zoom_pair_from_crop

ROOT = Path(__file__).resolve().parents[1]
SIFT_SCRIPT = ROOT / "scripts" / "sift_reference.py"
#: The large pair: a 6000x4000 high image cut from the photo enlarged to 9000x6000, seen in a
#: low image of at most 1800x1200 px (2.2 MP) zoomed out by 5 (footprint about 1200x800 px).
LARGE_HIGH = (6000, 4000)
LARGE_SCENE = (9000, 6000)
LARGE_RATIO = 5.0
LARGE_LOW_MAX = (1800, 1200)


def write_png(path: Path, image: np.ndarray) -> str:
    cv2.imwrite(str(path), np.clip(np.rint(image), 0, 255).astype(np.uint8))
    return str(path)


def run_child(cmd: Sequence[str]) -> Tuple[float, float, int]:
    """(wall seconds, peak resident MB, exit code) of one child process."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    return seconds, usage.ru_maxrss / 1024.0, proc.returncode


def load() -> str:
    return "/".join(f"{v:.1f}" for v in os.getloadavg())


def large_pair(photo: Path, seed: int):
    """The 6000x4000 / ~2 MP pair (the first seeded draw whose footprint fits the window)."""
    grey = cv2.imread(str(photo), cv2.IMREAD_GRAYSCALE).astype(np.float32)
    scene = cv2.resize(grey, LARGE_SCENE, interpolation=cv2.INTER_CUBIC)
    w, h = LARGE_HIGH
    x0, y0 = (LARGE_SCENE[0] - w) // 2, (LARGE_SCENE[1] - h) // 2
    for k in range(100):
        try:
            pair = zoom_pair_from_crop(scene, (x0, y0, w, h), LARGE_RATIO,
                                       np.random.default_rng([seed, 12, k]), LARGE_LOW_MAX,
                                       source=photo.name)
            return pair
        except ValueError:
            continue
    raise RuntimeError("no angle fits the large pair's window")


def main(argv: Sequence[str] = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared")
    ap.add_argument("--photos", type=int, default=0,
                    help="N photos spread evenly over the sorted list; 0 = all")
    ap.add_argument("--ratios", default="2,3,4,6,8,10")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-large", action="store_true")
    ap.add_argument("--no-process", action="store_true", help="skip the whole-process timing")
    ap.add_argument("--scalematch", default=str(Path(sys.executable).with_name("scalematch")),
                    help="the scalematch command (default: next to this Python)")
    args = ap.parse_args(argv)
    photos = sorted(p for p in (args.shared / "data" / "photos").iterdir()
                    if p.suffix.lower() in (".jpg", ".jpeg", ".png"))
    if 0 < args.photos < len(photos):
        photos = [photos[int(i)] for i in np.linspace(0, len(photos) - 1, args.photos)]
    ratios = [float(r) for r in args.ratios.split(",")]
    tmp = Path(tempfile.mkdtemp(prefix="speed-bench-"))
    pairs = list(pairs_from_photos(photos, ratios, args.seed))
    files = [(write_png(tmp / f"{k}_low.png", p.low), write_png(tmp / f"{k}_high.png", p.high))
             for k, p in enumerate(pairs)]
    sift_cmd = [sys.executable, str(SIFT_SCRIPT)]
    print(f"{len(pairs)} pairs from {len(photos)} photos, ratios {args.ratios}, seed {args.seed}"
          f"; load average before {load()}", file=sys.stderr)

    rows: List[str] = []
    if not args.no_process:
        sm_t, sift_t = [], []
        for k, (lo, hi) in enumerate(files):
            order = [0, 1] if k % 2 == 0 else [1, 0]
            got = {}
            for which in order:
                cmd = ([args.scalematch, lo, hi] if which == 0 else sift_cmd + [lo, hi])
                got[which] = run_child(cmd)[0]
            sm_t.append(got[0])
            sift_t.append(got[1])
        ratio = statistics.median(a / b for a, b in zip(sm_t, sift_t))
        rows.append(f"| whole process | {statistics.median(sm_t):.3f} | "
                    f"{statistics.median(sift_t):.3f} | {ratio:.2f} | {load()} |")

    sm_t, sift_t, sm_ok, sift_ok = [], [], 0, 0
    cfg = scalematch.Config()
    scalematch.match(pairs[0].low, pairs[0].high, cfg)  # warm-up: one-off library set-up
    match_baseline(pairs[0].low, pairs[0].high, "sift")
    for k, p in enumerate(pairs):
        order = [0, 1] if k % 2 == 0 else [1, 0]
        for which in order:
            t0 = time.perf_counter()
            if which == 0:
                r = scalematch.match(p.low, p.high, cfg)
                t = r.transform if r.matched else None
            else:
                t = match_baseline(p.low, p.high, "sift").transform
            dt = time.perf_counter() - t0
            ok = is_success(reprojection_error(t, p.truth, p.high.shape, p.low.shape))
            if which == 0:
                sm_t.append(dt)
                sm_ok += ok
            else:
                sift_t.append(dt)
                sift_ok += ok
    ratio = statistics.median(a / b for a, b in zip(sm_t, sift_t))
    rows.append(f"| in process | {statistics.median(sm_t):.3f} | {statistics.median(sift_t):.3f}"
                f" | {ratio:.2f} | {load()} |")
    n = len(pairs)
    print(f"success: scalematch {sm_ok}/{n}, SIFT {sift_ok}/{n}", file=sys.stderr)

    large = []
    if not args.no_large:
        biggest = max(photos, key=lambda p: p.stat().st_size)
        pair = large_pair(biggest, args.seed)
        lo = write_png(tmp / "large_low.png", pair.low)
        hi = write_png(tmp / "large_high.png", pair.high)
        del pair
        for _ in range(2):
            for name, cmd in (("scalematch", [args.scalematch, lo, hi]),
                              ("SIFT", sift_cmd + [lo, hi])):
                s, mb, code = run_child(cmd)
                large.append(f"| {name} | {s:.2f} | {mb:.0f} | {code} | {load()} |")
        low_shape = cv2.imread(lo, cv2.IMREAD_GRAYSCALE).shape
        large.insert(0, f"6000x4000 high ({biggest.name} enlarged), low {low_shape[1]}x"
                        f"{low_shape[0]}, ratio {LARGE_RATIO:g}, whole process (two rounds):\n\n"
                        "| method | seconds | peak MB | exit | load 1/5/15 min |\n|---|---|---|---|---|")

    print(f"| timing ({n} pairs) | scalematch median s | SIFT median s | median ratio | "
          "load 1/5/15 min after |\n|---|---|---|---|---|")
    print("\n".join(rows))
    print(f"\nsuccess (error < 3 px): scalematch {sm_ok}/{n}, SIFT {sift_ok}/{n}")
    if large:
        print("\n" + "\n".join(large))


if __name__ == "__main__":
    main()
