"""Throughput and memory of ``scalematch batch`` (docs/results/BATCH.md).

Usage: python scripts/batch_throughput.py [--pairs 200] [--memory-pairs 2000] [--repeats 2]

1. Cuts ``--pairs`` tiny synthetic zoom pairs from data/raccoon.jpg (``make_zoom_pair``: high
   200x150 px, low at most 200x150 px, ratios 2 to 4, seeded) into a temporary folder, as PNG
   files listed in pairs.csv. Nothing from ../shared is needed.
2. Times ``scalematch batch`` run as a user runs it (a subprocess: start-up and worker start
   included) on those pairs with the local pool at ``--jobs 1`` and ``--jobs 2``, and with
   ``--scheduler`` on a ``LocalCluster`` of 2 single-thread worker processes on 127.0.0.1
   (started beforehand, as a user's cluster is). pairs/s = pairs / wall time. ``--jobs 1``
   matches in the main process, where OpenCV uses all cores by default: it is run both so and
   with one OpenCV thread (OPENCV_FOR_THREADS_NUM=1), the one-worker baseline of the scaling.
3. Runs ``--jobs 2`` over ``--memory-pairs`` pairs (the same images under hard-linked names, so
   every row is a distinct pair) and samples the main process's resident memory (VmRSS in
   /proc/PID/status, Linux) each time another 500 lines are written, and its peak (VmHWM).
   ``--code DIR`` runs step 3 with the scalematch package found in DIR instead (to measure an
   older version the same way).

Every measurement records ``os.getloadavg()`` before and after: the machine may be shared.
Prints Markdown tables on stdout.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: (width, height) of the high image and the largest low image, px: a match takes ~0.1 s.
TINY = (200, 150)
#: Zoom ratios cycled over the pairs.
RATIOS = (2.0, 2.5, 3.0, 3.5, 4.0)
#: RSS is sampled each time this many more lines are in the output.
RSS_EVERY = 500
#: How often the main process's memory and the output are looked at, s.
POLL_S = 0.05


def make_pairs(folder: Path, n: int) -> Path:
    """``n`` tiny zoom pairs cut from data/raccoon.jpg, and pairs.csv listing them."""
    from scalematch.imageio import read_grey
    from scalematch.lab.synthetic import make_zoom_pair

    photo = read_grey(ROOT / "data" / "raccoon.jpg")
    rows = []
    for k in range(n):
        pair = make_zoom_pair(photo, RATIOS[k % len(RATIOS)], np.random.default_rng(k),
                              high_size=TINY, low_max=TINY)
        for name, img in ((f"low{k}.png", pair.low), (f"high{k}.png", pair.high)):
            cv2.imwrite(str(folder / name), np.clip(img, 0, 255).astype(np.uint8))
        rows.append(f"low{k}.png,high{k}.png\n")
    csv_path = folder / "pairs.csv"
    csv_path.write_text("".join(rows))
    return csv_path


def repeat_pairs(folder: Path, n_images: int, n: int) -> Path:
    """pairs_big.csv: ``n`` distinct rows over ``n_images`` pairs of images (hard links)."""
    rows = []
    for k in range(n):
        src = k % n_images
        for kind in ("low", "high"):
            link = folder / f"{kind}{src}_{k}.png"
            if not link.exists():
                os.link(folder / f"{kind}{src}.png", link)
        rows.append(f"low{src}_{k}.png,high{src}_{k}.png\n")
    csv_path = folder / "pairs_big.csv"
    csv_path.write_text("".join(rows))
    return csv_path


def batch_cmd(csv_path: Path, out: Path, *extra: str) -> List[str]:
    return [sys.executable, "-m", "scalematch.cli", "batch", str(csv_path), "--output", str(out),
            "-q", *extra]


def load() -> str:
    return "/".join(f"{x:.2f}" for x in os.getloadavg())


def _child_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed_run(csv_path: Path, out: Path, extra: Tuple[str, ...],
              env: Optional[Dict[str, str]] = None) -> Dict[str, object]:
    """Wall time of one batch run, the CPU time of its processes (the main process and its
    pool workers: not Dask workers), its lines, and the load average before and after."""
    out.unlink(missing_ok=True)
    before = load()
    cpu0 = _child_cpu()
    t0 = time.perf_counter()
    subprocess.run(batch_cmd(csv_path, out, *extra), check=False, env=env, cwd=csv_path.parent)
    wall = time.perf_counter() - t0
    cpu = _child_cpu() - cpu0
    lines = out.read_text().splitlines()
    matched = sum('"matched": true' in x for x in lines)
    return {"wall": wall, "cpu": cpu, "lines": len(lines), "matched": matched,
            "before": before, "after": load()}


def _status(pid: int) -> Optional[Dict[str, int]]:
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return None
    out = {}
    for line in text.splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            out[key] = int(value.split()[0])  # kB
    return out


def memory_run(csv_path: Path, out: Path, env: Dict[str, str]) -> Dict[str, object]:
    """RSS of the main process each RSS_EVERY lines, and its peak, over one --jobs 2 run."""
    out.unlink(missing_ok=True)
    before = load()
    t0 = time.perf_counter()
    # run from the pairs' folder: `python -m` puts the working directory first on sys.path
    proc = subprocess.Popen(batch_cmd(csv_path, out, "--jobs", "2"), env=env, cwd=csv_path.parent)
    samples: List[Tuple[int, int]] = []
    peak = 0
    next_at = RSS_EVERY
    while proc.poll() is None:
        status = _status(proc.pid)
        done = out.read_bytes().count(b"\n") if out.exists() else 0
        if status:
            peak = max(peak, status.get("VmHWM", 0))
            if done >= next_at:
                samples.append((done, status["VmRSS"]))
                next_at += RSS_EVERY
        time.sleep(POLL_S)
    return {"samples": samples, "peak_kb": peak, "wall": time.perf_counter() - t0,
            "lines": out.read_bytes().count(b"\n"), "before": before, "after": load()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pairs", type=int, default=200)
    parser.add_argument("--memory-pairs", type=int, default=2000, help="0: no memory run")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--code", type=Path, default=None,
                        help="run the memory measurement with the scalematch package in DIR")
    parser.add_argument("--skip-throughput", action="store_true")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="scalematch-batch-") as tmp:
        folder = Path(tmp)
        csv_path = make_pairs(folder, args.pairs)
        out = folder / "r.jsonl"
        print(f"{args.pairs} pairs of {TINY[0]}x{TINY[1]} px, {os.cpu_count()} cores; "
              f"load average (1/5/15 min) given before and after each run\n")
        if not args.skip_throughput:
            from distributed import LocalCluster

            print("| runner | run | wall s | pairs/s | CPU s | lines | matched | load before | "
                  "after |")
            print("|---|---|---|---|---|---|---|---|---|")
            one_thread = dict(os.environ, OPENCV_FOR_THREADS_NUM="1")
            with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                              host="127.0.0.1", dashboard_address=None) as cluster:
                runners = [
                    ("--jobs 1, one OpenCV thread (1 worker)", ("--jobs", "1"), one_thread),
                    ("--jobs 1 as shipped (OpenCV's threads)", ("--jobs", "1"), None),
                    ("local pool, --jobs 2", ("--jobs", "2"), None),
                    ("Dask LocalCluster, 2 workers", ("--scheduler", cluster.scheduler_address),
                     None)]
                for r in range(args.repeats):
                    for name, extra, env in runners:
                        m = timed_run(csv_path, out, extra, env)
                        cpu = f"{m['cpu']:.1f}" if "--scheduler" not in extra else "-"
                        print(f"| {name} | {r + 1} | {m['wall']:.1f} | "
                              f"{args.pairs / m['wall']:.2f} | {cpu} | {m['lines']} | "
                              f"{m['matched']} | {m['before']} | {m['after']} |", flush=True)
        if not args.memory_pairs:
            return
        big = repeat_pairs(folder, args.pairs, args.memory_pairs)
        env = dict(os.environ)
        if args.code is not None:
            env["PYTHONPATH"] = str(args.code.resolve())
        code = subprocess.run([sys.executable, "-c", "import scalematch; print(scalematch.__file__)"],
                              env=env, cwd=folder, capture_output=True, text=True).stdout.strip()
        m = memory_run(big, out, env)
        print(f"\n{args.memory_pairs} pairs, --jobs 2 (code: {code}): {m['lines']} lines in "
              f"{m['wall']:.0f} s, load average {m['before']} before, {m['after']} after\n")
        print("| lines written | main process RSS, MB |")
        print("|---|---|")
        for done, rss in m["samples"]:
            print(f"| {done} | {rss / 1024:.1f} |")
        print(f"| peak (VmHWM) | {m['peak_kb'] / 1024:.1f} |")


if __name__ == "__main__":
    main()
