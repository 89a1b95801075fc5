"""Would an index of the coarser image's descriptors make the nearest neighbours of a "no" cheaper?

Usage: python scripts/knn_index.py [--nulls bench-out/nulls/pairs-seed0] [--every 60]

Runs the default search on every ``--every``-th stored null pair of ``scalematch lab nulls``
(given order), records each nearest-neighbour query it makes (the probe's and the full
searches': ``matcher._knn``'s two descriptor sets), then replays the queries against the same
coarser descriptors with:

* the exact product of ``matcher._knn`` (what the search does);
* OpenCV's brute force (``cv2.BFMatcher``, L2, k = 2): exact too;
* OpenCV's FLANN KD-trees (``trees``, ``checks``), the index built once per coarser set.

For each: the time of the queries (the index build counted apart), and how many of the exact
ratio-test survivors (``MatcherParams.ratio``) it keeps with the same neighbour, and how many
survivors it adds. One thread (``cv2.setNumThreads(1)``; run with ``OMP_NUM_THREADS=1``).
Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Callable, List, Tuple

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scalematch import Config, match  # noqa: E402
from scalematch.lab.nulls import read_manifest  # noqa: E402
from scalematch.stages import matcher  # noqa: E402

#: (name, trees, checks) of the FLANN settings tried: from a single tree and few checks to
#: eight trees and 128 checks (FLANN's own default is 4 trees and 32 checks)
FLANN_SETTINGS = ((1, 16), (4, 32), (4, 64), (8, 128))
RATIO = Config().matcher.ratio


def recorded_queries(low: np.ndarray, high: np.ndarray) -> List[Tuple[np.ndarray, np.ndarray]]:
    """Every (query, coarser) descriptor pair the default search gives ``matcher._knn``."""
    seen: List[Tuple[np.ndarray, np.ndarray]] = []
    exact = matcher._knn

    def spy(a, b, k):
        seen.append((a.copy(), b))
        return exact(a, b, k)

    matcher._knn = spy
    try:
        match(low, high, Config())
    finally:
        matcher._knn = exact
    return seen


def survivors(idx: np.ndarray, dist: np.ndarray) -> dict:
    """query row -> neighbour, for the rows that pass the ratio test."""
    keep = dist[:, 0] <= RATIO * dist[:, 1]
    return dict(zip(np.nonzero(keep)[0].tolist(), idx[keep, 0].tolist()))


def from_dmatches(found) -> Tuple[np.ndarray, np.ndarray]:
    idx = np.array([[m.trainIdx for m in pair[:2]] for pair in found]).reshape(-1, 2)
    dist = np.array([[m.distance for m in pair[:2]] for pair in found]).reshape(-1, 2)
    return idx, dist


def timed(fn: Callable[[], Tuple[np.ndarray, np.ndarray]]):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--nulls", default="bench-out/nulls/pairs-seed0")
    ap.add_argument("--every", type=int, default=60)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    folder = Path(args.nulls)
    entries = [read_manifest(folder)[k] for k in sorted(read_manifest(folder))][::args.every]
    if not entries:
        sys.exit(f"no stored null pairs in {folder}: run `scalematch lab nulls` first")
    methods = ["exact product", "cv2.BFMatcher"] + [f"FLANN {t} trees, {c} checks"
                                                   for t, c in FLANN_SETTINGS]
    secs = dict.fromkeys(methods, 0.0)
    build = dict.fromkeys(methods, 0.0)
    kept = dict.fromkeys(methods, 0)
    added = dict.fromkeys(methods, 0)
    n_exact = n_queries = n_rows = 0
    for e in entries:
        low = cv2.imread(str(folder / e["low_file"]), cv2.IMREAD_GRAYSCALE)
        high = cv2.imread(str(folder / e["high_file"]), cv2.IMREAD_GRAYSCALE)
        queries = [(a, b) for a, b in recorded_queries(low, high) if len(a) and len(b) >= 2]
        indexes = {}
        for a, b in queries:
            n_queries += 1
            n_rows += len(a)
            truth, t = timed(lambda: matcher._knn(a, b, 2))
            secs["exact product"] += t
            ref = survivors(*truth)
            n_exact += len(ref)
            results = {"exact product": truth}
            bf = cv2.BFMatcher(cv2.NORM_L2)
            results["cv2.BFMatcher"], t = timed(lambda: from_dmatches(bf.knnMatch(a, b, k=2)))
            secs["cv2.BFMatcher"] += t
            for (trees, checks), name in zip(FLANN_SETTINGS, methods[2:]):
                key = (id(b), trees, checks)
                if key not in indexes:  # one index per coarser descriptor set
                    fl = cv2.FlannBasedMatcher(dict(algorithm=1, trees=trees),
                                               dict(checks=checks))
                    _, t = timed(lambda: (fl.add([b]), fl.train()))
                    build[name] += t
                    indexes[key] = fl
                results[name], t = timed(lambda: from_dmatches(indexes[key].knnMatch(a, k=2)))
                secs[name] += t
            for name, (idx, dist) in results.items():
                got = survivors(idx, dist)
                kept[name] += sum(got.get(r) == j for r, j in ref.items())
                added[name] += sum(r not in ref for r in got)
        print(f"{e['pair_id']}: {len(queries)} queries", file=sys.stderr)
    print(f"{len(entries)} null pairs (every {args.every}th of {folder}), {n_queries} queries, "
          f"{n_rows} query rows, {n_exact} exact ratio-test survivors\n")
    print("| nearest neighbours | queries, s | index builds, s | exact survivors kept "
          "| survivors added |")
    print("|---|---:|---:|---:|---:|")
    for name in methods:
        print(f"| {name} | {secs[name]:.2f} | {build[name]:.2f} | "
              f"{100.0 * kept[name] / max(n_exact, 1):.0f} % | {added[name]} |")


if __name__ == "__main__":
    main()
