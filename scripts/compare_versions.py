"""Plain zoom pairs, two versions of scalematch, alternately in one run (issue 9's "as good and
no slower than today").

Each version runs in its own persistent worker process with its source tree first on
``sys.path``; the pairs (EVALUATION.md, ``scalematch.lab.synthetic.pairs_from_photos``) are made
once and given to the two workers in turn, pair by pair, so both see the same machine load.
Prints success per ratio, median error of the successes and the median in-process time of each.

    python scripts/compare_versions.py --old ../old-checkout --photos 38
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RATIOS = (2, 3, 4, 6, 8, 10)


def _worker(tree: str, jobs, results) -> None:
    sys.path.insert(0, tree)
    from scalematch.pipeline import match  # noqa: E402 - the version under test

    while True:
        job = jobs.get()
        if job is None:
            return
        k, low, high = job
        t0 = time.perf_counter()
        r = match(low, high)
        results.put((k, time.perf_counter() - t0, r.transform if r.matched else None))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", required=True, help="source tree of the older version")
    ap.add_argument("--new", default=str(ROOT), help="source tree of the newer version")
    ap.add_argument("--photos", type=int, default=38, help="first N photos of ../shared")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    sys.path.insert(0, a.new)
    from scalematch.lab.datasets import find_shared, list_photos
    from scalematch.lab.evaluation import is_success, reprojection_error
    from scalematch.lab.synthetic import pairs_from_photos
    from scalematch.stages.decision import mean_transfer_gap

    shared = find_shared()
    if shared is None:
        sys.exit("../shared is absent")
    pairs = list(pairs_from_photos(list_photos(shared)[:a.photos], RATIOS, a.seed))
    ctx = mp.get_context("spawn")
    workers = {}
    for name, tree in (("old", a.old), ("new", a.new)):
        jobs, results = ctx.Queue(), ctx.Queue()
        proc = ctx.Process(target=_worker, args=(str(Path(tree).resolve()), jobs, results))
        proc.start()
        workers[name] = (proc, jobs, results)
    rows = {name: [] for name in workers}
    found = {name: [] for name in workers}  # the transforms, to compare the answers
    load = os.getloadavg()
    for k, p in enumerate(pairs):
        order = ("old", "new") if k % 2 == 0 else ("new", "old")
        for name in order:
            _, jobs, results = workers[name]
            jobs.put((k, p.low, p.high))
            _, secs, t = results.get()
            err = reprojection_error(t, p.truth, p.high.shape, p.low.shape)
            rows[name].append((p.ratio, secs, err, is_success(err)))
            found[name].append(t)
    for proc, jobs, _ in workers.values():
        jobs.put(None)
        proc.join()
    print(f"{len(pairs)} pairs ({a.photos} photos x ratios {RATIOS}), seed {a.seed}, load average "
          f"at start {load[0]:.1f}, at end {os.getloadavg()[0]:.1f}")
    print("| version | " + " | ".join(f"x{r}" for r in RATIOS) + " | all | median error px "
          "| median s |")
    print("|---|" + "---:|" * (len(RATIOS) + 3))
    for name, rs in rows.items():
        per = [sum(ok for r, _, _, ok in rs if r == ratio) for ratio in RATIOS]
        n = len(rs) // len(RATIOS)
        errs = [e for _, _, e, ok in rs if ok]
        print(f"| {name} | " + " | ".join(f"{v}/{n}" for v in per)
              + f" | {sum(per)}/{len(rs)} | {np.median(errs):.3f} | "
              f"{np.median([s for _, s, _, _ in rs]):.3f} |")
    ratio = np.median([s for _, s, _, _ in rows["new"]]) / np.median(
        [s for _, s, _, _ in rows["old"]])
    print(f"median time new / old: {ratio:.2f}")
    same = sum((a is None and b is None) or (a is not None and b is not None
                                             and np.array_equal(a, b))
               for a, b in zip(found["old"], found["new"]))
    gaps = [mean_transfer_gap(a, b, p.high.shape) for a, b, p in
            zip(found["old"], found["new"], pairs) if a is not None and b is not None]
    print(f"answers: {same}/{len(pairs)} identical; both matched {len(gaps)}, mean transfer gap "
          f"median {np.median(gaps):.4f} px, max {np.max(gaps):.4f} px")


if __name__ == "__main__":
    main()
