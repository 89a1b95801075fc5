"""What ``--no-views`` buys and costs: the default search against the plain search alone.

Usage: python scripts/fast_no.py [--every 4] [--sets zoom,tilted,unrelated] [--big-rounds 3]
       [--methods default,no-views,sift]

The default search tries tilted views of the finer image when the plain search finds nothing,
in both orders: that is most of the time of a "no". The preset ``no-views`` (``--no-views`` on
the command line) searches the image itself in both orders only. In one process, alternately
pair by pair (the order of the methods turned each pair), this script runs the default, the
preset and the SIFT reference (``scalematch.lab.baselines``, EVALUATION.md), or the
``--methods`` named (``sift`` and any ``Config.preset``: ``tilt-4``, ``budget-1s``, ...), on:

* the stored null pairs of ``scalematch lab nulls`` (every ``--every``-th pair of ``--nulls``,
  by default ``bench-out/nulls/pairs-seed0``, where ``scalematch lab nulls`` stores them; both
  orders): the time of a "no", and any claim (false). Skipped, with a note, when the folder
  holds no pairs;
* the sets of ``scalematch lab real-pairs`` named in ``--sets`` (every 3rd photo, seed 0):
  pairs solved (grid error under 3 px), wrong claims, median time; SIFT fits each set's model
  (a homography on tilted pairs), as in ``lab real-pairs``;

then, as whole processes, 12-16 MP unrelated pairs (the first ``--big-pairs`` of
``BIG_PAIRS``; ``scalematch A B -q`` with and without ``--no-views``, ``--big-rounds`` rounds
alternately; seconds and peak memory from ``/usr/bin/time`` when it exists), with what the
time of a "no" follows: the views the search probed and matched in full, and the points of
the first scale. Prints Markdown tables.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

from compare_versions import _Stored, _stored_nulls  # noqa: E402
from scalematch import Config, match  # noqa: E402
from scalematch.lab.baselines import match_baseline  # noqa: E402
from scalematch.lab.datasets import find_shared, list_photos  # noqa: E402
from scalematch.lab.realpairs import PHOTO_STEP, canonical, pair_error, synthetic_sets  # noqa: E402
from scalematch.lab.evaluation import is_success  # noqa: E402

METHODS = ("default", "no-views", "sift")  #: the methods run unless ``--methods`` says
#: unrelated photos of 16 and 12 MP (4608x3456 and 4032x3024 px); the first is the pair the
#: design notes quote
BIG_PAIRS = (("snowpeak_IMG_2168.JPG", "monstree_IMG_1042.JPG"),
             ("snowpeak_IMG_2280.JPG", "jpegtest_012mp-bus.jpg"),
             ("monstree_IMG_1029.JPG", "snowpeak_IMG_2186.JPG"),
             ("snowpeak_IMG_2282.JPG", "monstree_IMG_1046.JPG"))


def run(method: str, low: np.ndarray, high: np.ndarray, model: str = "similarity"):
    """(transform high -> low or None, maps high to low, seconds, CPU seconds of every
    thread); SIFT fits ``model``. The CPU time depends less than the wall time on what else
    the machine runs."""
    t0, c0 = time.perf_counter(), time.process_time()
    if method == "sift":
        t, fwd = match_baseline(low, high, "sift", model=model).transform, True
    else:
        r = match(low, high, configured(method))
        t, fwd = (r.transform if r.matched else None), r.order == "given"
    return t, fwd, time.perf_counter() - t0, time.process_time() - c0


def configured(method: str) -> Config:
    """The Config of a method: a preset, and with "+path=value" the values of ``--set`` on it
    (``tilt-4+views.full_searches=2``; ``scalematch.lab.regress.configured``)."""
    from scalematch.lab.regress import configured as preset_with
    from scalematch.options import set_path

    return preset_with(method, Config, set_path)


def alternate(items, judge, methods=METHODS):
    """Each item run by every method, the methods' order turned each item; rows per method."""
    rows = {m: [] for m in methods}
    for n, item in enumerate(items):
        order = methods[n % len(methods):] + methods[:n % len(methods)]
        for m in order:
            t, fwd, sec, cpu = run(m, item.low, item.high, getattr(item, "model", "similarity"))
            rows[m].append((judge(item, t, fwd), sec, cpu))
    return rows


def nulls_table(folder: Path, every: int, methods=METHODS) -> str:
    pairs = _stored_nulls(folder, every)
    runs = pairs + [_Stored(p.high, p.low) for p in pairs]  # both orders
    rows = alternate(runs, lambda item, t, fwd: t is not None, methods)
    out = [f"Null runs: every {every}th stored pair of {folder}, both orders ({len(runs)} runs)",
           "", "| method | runs | claims (all false) | median s | 90th percentile s | "
           "median CPU s |", "|---|---:|---:|---:|---:|---:|"]
    for m in methods:
        secs = [r[1] for r in rows[m]]
        out.append(f"| {m} | {len(secs)} | {sum(r[0] for r in rows[m])} | "
                   f"{np.median(secs):.3f} | {np.percentile(secs, 90):.3f} | "
                   f"{np.median([r[2] for r in rows[m]]):.3f} |")
    return "\n".join(out)


def sets_table(shared: Path, names, methods=METHODS) -> str:
    sets = synthetic_sets(list_photos(shared)[::PHOTO_STEP], 0, wanted=names)
    out = ["| set | method | pairs | solved | wrong claims | median s | median CPU s |",
           "|---|---|---:|---:|---:|---:|---:|"]
    for name in names:
        def judge(pair, t, fwd):
            if pair.truth is None:
                return (False, t is not None)
            ok = t is not None and is_success(pair_error(pair, canonical(pair, t, fwd)))
            return (ok, t is not None and not ok)

        rows = alternate(sets[name], judge, methods)
        for m in methods:
            rs = rows[m]
            out.append(f"| {name} | {m} | {len(rs)} | {sum(r[0][0] for r in rs)} | "
                       f"{sum(r[0][1] for r in rs)} | {np.median([r[1] for r in rs]):.3f} | "
                       f"{np.median([r[2] for r in rs]):.3f} |")
        if {"default", "no-views"} <= set(methods):
            out.append(f"| {name} | default / no-views, median of the pairs' ratios | | | | "
                       f"{speedup(rows, 1):.1f}x | {speedup(rows, 2):.1f}x |")
    return "\n".join(out)


def speedup(rows, k: int) -> float:
    """The median over the items of the default's time over ``no-views``'s on the same item
    (``k``: 1 wall seconds, 2 CPU seconds), the two run one after the other."""
    return float(np.median([a[k] / b[k] for a, b in zip(rows["default"], rows["no-views"])]))


def big_run(exe: str, a: str, b: str, no_views: bool) -> dict:
    """``scalematch A B -q`` as a whole process: seconds, peak MB, exit code, CPU seconds, and
    from its JSON the views probed and matched in full, and the points at the first scale."""
    timer = ["/usr/bin/time", "-f", "%e %M %U %S"] if Path("/usr/bin/time").exists() else []
    with tempfile.TemporaryDirectory() as out_dir:
        result = Path(out_dir) / "result.json"
        cmd = timer + [exe, a, b, "-q", "--out-dir", out_dir, "--json", str(result)]
        cmd += ["--no-views"] if no_views else []
        t0 = time.perf_counter()
        p = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        r = json.loads(result.read_text()) if result.is_file() else {}
    measured = p.stderr.strip().splitlines()[-1].split() if timer else ["nan"] * 4
    steps = r.get("search", [])
    return {"s": wall, "mb": float(measured[1]) / 1024, "exit": p.returncode,
            "cpu": float(measured[2]) + float(measured[3]),
            "probed": sum(x["views"] for x in steps), "full": sum(x["full"] for x in steps),
            "points": r["scales"][0]["points"] if r.get("scales") else 0}


def big_table(shared: Path, rounds: int, pairs: int = 1) -> str:
    exe = shutil.which("scalematch") or str(Path(sys.executable).parent / "scalematch")
    out = [f"Unrelated 12-16 MP pairs, `scalematch A B -q` as a whole process, {rounds} rounds "
           f"alternately; views probed / matched in full, points at the first scale", "",
           "| pair | search | seconds | CPU s | peak MB | views probed / in full | points | exit |",
           "|---|---|---|---|---|---|---:|---|"]
    for names in BIG_PAIRS[:pairs]:
        a, b = (str(shared / "data" / "photos" / n) for n in names)
        res = {"default": [], "no-views": []}
        for k in range(rounds):
            for opt in (("default", "no-views") if k % 2 == 0 else ("no-views", "default")):
                res[opt].append(big_run(exe, a, b, opt == "no-views"))
        for opt, rs in res.items():
            secs = ", ".join(f"{r['s']:.2f}" for r in rs)
            cpus = ", ".join(f"{r['cpu']:.2f}" for r in rs)
            mbs = ", ".join(f"{r['mb']:.0f}" for r in rs)
            out.append(f"| {names[0]} / {names[1]} | {opt} | {secs} | {cpus} | {mbs} | "
                       f"{rs[0]['probed']} / {rs[0]['full']} | {rs[0]['points']} | "
                       f"{', '.join(str(r['exit']) for r in rs)} |")
        ratio = {k: np.median([r[k] for r in res["default"]]) / np.median(
            [r[k] for r in res["no-views"]]) for k in ("s", "cpu")}
        out.append(f"| | default / no-views | {ratio['s']:.1f}x | {ratio['cpu']:.1f}x | | | | |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--every", type=int, default=4)
    ap.add_argument("--nulls", default=str(ROOT / "bench-out" / "nulls" / "pairs-seed0"),
                    help="a pairs folder of `scalematch lab nulls` (its manifest.json and PNGs)")
    ap.add_argument("--sets", default="zoom,tilted,unrelated")
    ap.add_argument("--big-rounds", type=int, default=3)
    ap.add_argument("--big-pairs", type=int, default=1, help=f"how many of the "
                    f"{len(BIG_PAIRS)} 12-16 MP unrelated pairs (BIG_PAIRS)")
    ap.add_argument("--methods", default=",".join(METHODS),
                    help="sift and Config presets, comma-separated, each with values set as "
                         "+path=value (tilt-4+views.full_searches=2; the big pair: "
                         "always default and no-views)")
    a = ap.parse_args()
    methods = tuple(m for m in a.methods.split(",") if m)
    for m in methods:
        if m != "sift":
            configured(m)  # an unknown name fails here, before any run
    shared = find_shared()
    if shared is None:
        sys.exit("../shared is absent")
    print(f"load average at the start {os.getloadavg()[0]:.2f}\n")
    if a.big_rounds:
        print(big_table(shared, a.big_rounds, a.big_pairs) + "\n")
    if a.every and not (Path(a.nulls) / "manifest.json").is_file():
        print(f"No stored null pairs in {a.nulls}: `scalematch lab nulls --limit 40` makes 40 "
              "(and runs them); the null table is skipped.\n")
    elif a.every:
        print(nulls_table(Path(a.nulls), a.every, methods) + "\n")
    names = [s for s in a.sets.split(",") if s]
    if names:
        print(sets_table(shared, names, methods) + "\n")
    print(f"load average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
