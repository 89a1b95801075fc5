"""Two versions of scalematch on the same pairs, alternately in one run: the same answers? how fast?

Usage: python scripts/compare_versions.py --old OLD_SOURCE_TREE [--new TREE] [--photos 38]
       [--swapped] [--unrelated N] [--nulls FOLDER --every N]

Each version runs in its own persistent worker process with its source tree first on
``sys.path``; the pairs (EVALUATION.md, ``scalematch.lab.synthetic.pairs_from_photos``) are made
once and given to the two workers in turn, pair by pair, so both see the same machine load.
Prints success per ratio, median error of the successes and the median in-process time of each,
and the median time of a "no" on the unrelated pairs.

    python scripts/compare_versions.py --old ../old-checkout --photos 38
    python scripts/compare_versions.py --old ../old-checkout --photos 13 --swapped --unrelated 50
    python scripts/compare_versions.py --old ../old-checkout --photos 0 --nulls bench-out/nulls/pairs-seed0 --every 20

``--swapped`` gives each pair in the other order too (the answer must still map the finer image
into the coarser one); ``--unrelated N`` adds N pairs of unrelated photos (the low image of one
scene, the high image of another), where any match claimed is false. ``--nulls FOLDER`` adds
the null pairs that ``scalematch lab nulls`` stored there (every ``--every``-th, in both orders;
any claim is false): the time of a "no".
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


class _Stored:
    """A null pair read from a folder of ``scalematch lab nulls`` (no truth: any claim is false)."""

    def __init__(self, low: np.ndarray, high: np.ndarray) -> None:
        self.low, self.high, self.ratio, self.truth = low, high, float("nan"), None


def _stored_nulls(folder: Path, every: int) -> list:
    """Every ``every``-th null pair (not the true ones) of a ``lab nulls`` pairs folder."""
    import cv2
    from scalematch.lab.nulls import TRUE_KIND, read_manifest

    stored = read_manifest(folder)
    if not stored:
        sys.exit(f"no stored null pairs in {folder}: `scalematch lab nulls --out-dir DIR` stores "
                 "them in DIR/pairs-seed0")
    entries = [e for _, e in sorted(stored.items()) if e["kind"] != TRUE_KIND][::max(every, 1)]
    return [_Stored(cv2.imread(str(folder / e["low_file"]), cv2.IMREAD_GRAYSCALE),
                    cv2.imread(str(folder / e["high_file"]), cv2.IMREAD_GRAYSCALE))
            for e in entries]


def _join(workers: dict) -> None:
    for proc, jobs, _ in workers.values():
        jobs.put(None)
        proc.join()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", required=True, help="source tree of the older version")
    ap.add_argument("--new", default=str(ROOT), help="source tree of the newer version")
    ap.add_argument("--photos", type=int, default=38, help="first N photos of ../shared")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--ratios", default=",".join(map(str, RATIOS)),
                    help="comma-separated ratios (default: %(default)s)")
    ap.add_argument("--swapped", action="store_true", help="each pair in both orders")
    ap.add_argument("--unrelated", type=int, default=0, help="unrelated pairs added")
    ap.add_argument("--nulls", help="folder of null pairs stored by `scalematch lab nulls`")
    ap.add_argument("--every", type=int, default=1, help="every N-th null pair (default 1)")
    a = ap.parse_args()
    ratios = tuple(float(r) for r in a.ratios.split(","))
    sys.path.insert(0, a.new)
    from scalematch.lab.datasets import find_shared, list_photos
    from scalematch.lab.evaluation import is_success, reprojection_error
    from scalematch.lab.datasets import scene_of
    from scalematch.lab.synthetic import pairs_from_photos, unrelated_from_pairs
    from scalematch.stages.decision import mean_transfer_gap

    shared = find_shared()
    if shared is None:
        sys.exit("../shared is absent")
    pairs = list(pairs_from_photos(list_photos(shared)[:a.photos], ratios, a.seed))
    nulls = unrelated_from_pairs(pairs, a.unrelated, np.random.default_rng([a.seed, 1]), scene_of)
    # (kind, pair, swapped): the answer is judged against pair.truth either way round
    jobs_list = [("zoom", p, False) for p in pairs]
    jobs_list += [("swapped", p, True) for p in pairs] if a.swapped else []
    jobs_list += [("unrelated", p, False) for p in nulls]
    stored = _stored_nulls(Path(a.nulls), a.every) if a.nulls else []
    jobs_list += [("null", p, swapped) for p in stored for swapped in (False, True)]
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
    claims = {name: 0 for name in workers}
    null_secs = {name: [] for name in workers}
    null_claims = {name: 0 for name in workers}
    no_secs = {name: [] for name in workers}  # the unrelated pairs' times: a "no"
    for k, (kind, p, swapped) in enumerate(jobs_list):
        order = ("old", "new") if k % 2 == 0 else ("new", "old")
        for name in order:
            _, jobs, results = workers[name]
            jobs.put((k, p.high, p.low) if swapped else (k, p.low, p.high))
            _, secs, t = results.get()
            found[name].append(t)
            if kind == "null":
                null_claims[name] += t is not None
                null_secs[name].append(secs)
                continue
            if kind == "unrelated":
                claims[name] += t is not None
                no_secs[name].append(secs)
                continue
            err = reprojection_error(t, p.truth, p.high.shape, p.low.shape)
            rows[name].append((p.ratio, secs, err, is_success(err)))
    _join(workers)
    print(f"{len(pairs)} pairs ({a.photos} photos x ratios {ratios}){' in both orders' if a.swapped else ''}"
          f", {len(nulls)} unrelated, {2 * len(stored)} stored null runs, seed {a.seed}, load "
          f"average at start {load[0]:.1f}, at end {os.getloadavg()[0]:.1f}")
    if stored:
        for name, secs in null_secs.items():
            print(f"null runs, {name}: median {np.median(secs):.3f} s, mean {np.mean(secs):.3f} s")
        print(f"null median time new / old: "
              f"{np.median(null_secs['new']) / np.median(null_secs['old']):.3f}")
        print(f"claims on the stored null runs: old {null_claims['old']}, "
              f"new {null_claims['new']}")
    same = sum((a is None and b is None) or (a is not None and b is not None
                                             and np.array_equal(a, b))
               for a, b in zip(found["old"], found["new"]))
    gaps = [mean_transfer_gap(a, b, p.high.shape) for a, b, (_, p, _) in
            zip(found["old"], found["new"], jobs_list) if a is not None and b is not None]
    gap_text = (f", mean transfer gap median {np.median(gaps):.4f} px, max {np.max(gaps):.4f} px"
                if gaps else "")
    print(f"answers: {same}/{len(jobs_list)} identical; both matched {len(gaps)}{gap_text}")
    if not pairs:
        return
    print("| version | " + " | ".join(f"x{r:g}" for r in ratios) + " | all | median error px "
          "| median s | false claims |")
    print("|---|" + "---:|" * (len(ratios) + 4))
    for name, rs in rows.items():
        per = [sum(ok for r, _, _, ok in rs if r == ratio) for ratio in ratios]
        n = len(rs) // len(ratios)
        errs = [e for _, _, e, ok in rs if ok]
        print(f"| {name} | " + " | ".join(f"{v}/{n}" for v in per)
              + f" | {sum(per)}/{len(rs)} | {np.median(errs):.3f} | "
              f"{np.median([s for _, s, _, _ in rs]):.3f} | {claims[name]}/{len(nulls)} |")
    ratio = np.median([s for _, s, _, _ in rows["new"]]) / np.median(
        [s for _, s, _, _ in rows["old"]])
    print(f"median time new / old: {ratio:.2f}")
    if no_secs["new"]:
        old_no, new_no = (np.median(no_secs[n]) for n in ("old", "new"))
        pair = np.median(np.asarray(no_secs["new"]) / np.asarray(no_secs["old"]))
        print(f"unrelated pairs (a 'no'): median old {old_no:.3f} s, new {new_no:.3f} s; "
              f"new / old {new_no / old_no:.3f}, pair by pair {pair:.3f}")


if __name__ == "__main__":
    main()
