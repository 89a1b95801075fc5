"""Tilted, perspective and oblique pairs: configurations of scalematch's views against SIFT.

Usage: python scripts/steep_views.py [--tilts 6,8] [--ratios 2,4] [--photo-step 3]
       [--variants default,tilt-4] [--swapped] [--out FILE.jsonl]
       python scripts/steep_views.py --kind perspective --tilts 4,8 [...]
       python scripts/steep_views.py --kind oblique --variants default,no-coarser --swapped
       python scripts/steep_views.py --kind oxford --variants homography,default --swapped

``--kind perspective``: the perspective zoom pairs instead (``lab.realpairs.perspective_pairs``:
the local ratio spans [ratio, ratio x spread] over the footprint, exact homography truth); the
``--tilts`` are then the spreads. ``--kind oblique``: the pairs whose finer image is the oblique
one (``lab.realpairs.oblique_pairs`` at ``synthetic.OBLIQUE_CASES``; ``--tilts`` and ``--ratios``
are not used). ``--kind oxford``: graf 1->5 and 1->6, wall 1->6 (``OXFORD_PAIRS``; with
``--swapped`` also 5->1, 6->1), the published homographies as truth.

The pairs are ``lab.realpairs``' tilted set (``synthetic.make_tilted_pair``: the same seed, the
same photos, every 3rd of ../shared/data/photos, exact affine truth, EVALUATION-TILT.md) at
other tilts. Each pair is given in the given order (finer second), and with ``--swapped`` also
in the other. Variants are scalematch configurations (``VARIANTS``); SIFT (ratio test 0.8 +
RANSAC homography, as in ``lab real-pairs``) runs on the same pair right after them, in this
process, one OpenCV thread. Success: grid error < 3 px (``lab.evaluation``). Prints one row per
pair and a table per (variant, tilt); rows go to ``--out`` (resumed when it exists).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import cv2  # noqa: E402

from scalematch import Config, match  # noqa: E402
from scalematch.lab.datasets import find_shared, list_photos  # noqa: E402
from scalematch.lab.evaluation import is_success  # noqa: E402
from scalematch.lab.realpairs import (STEEP_TILTS, canonical, oblique_pairs,  # noqa: E402
                                      oxford_pairs, pair_error, perspective_pairs, run_sift,
                                      swap, tilted_pairs)
from scalematch.lab.synthetic import OBLIQUE_CASES  # noqa: E402
from scalematch.stages.views import ViewParams  # noqa: E402

#: scalematch configurations compared (``--variants``; docs/design/VIEWS.md): the default's
#: passes of views are t = 2, then 4, then 6 and 8, each run only when the earlier found nothing
VARIANTS = {
    "default": Config(),
    # the default without its third pass (t = 6 and 8)
    "tilt-4": Config.preset("tilt-4"),
    # what a user who knows the pair is seen in perspective would ask for (the default's
    # answer allowed as far as a homography: the same as the default), and a homography
    # searched for at every scale
    "homography": Config.preset("homography"),
    "homography-searched": Config.preset("homography-searched"),
    "affine": Config.preset("affine"),
    # the default with a time budget of 1 s: what the budget costs on pairs that have an answer
    "budget-1s": Config.preset("budget-1s"),
    # the default without the views of the coarser image
    "no-coarser": Config(views=ViewParams(coarser=False)),
    # a third pass of tilt 8 alone (a sampling ratio of 2: 2, 4, 8), 20 views instead of 35
    "steep8": Config(views=ViewParams(passes=((2.0,), (4.0,), (8.0,)))),
    # the coarser image's views in one direction only (the smaller coarser image's)
    "coarser-one": Config(views=ViewParams(coarser_directions="one")),
}

#: The Oxford viewpoint pairs (graf 1->5 and 1->6, wall 1->6; both directions with --swapped)
OXFORD_PAIRS = ("graf 1->5", "graf 1->6", "wall 1->6")


def make_pairs(paths, tilts, ratios, seed, swapped, kind="tilted", shared=None):
    """``lab.realpairs``' tilted pairs at these tilts (perspective pairs at these spreads,
    oblique pairs, the Oxford pairs of ``OXFORD_PAIRS``), and with ``swapped`` each one
    swapped (Oxford: its N->1 pair)."""
    if kind == "oxford":
        every = oxford_pairs(shared)
        names = [n for n in OXFORD_PAIRS] + (
            [f"{n.split()[0]} {n.split()[1][::-1].replace('>-', '->')}" for n in OXFORD_PAIRS]
            if swapped else [])
        return [p for n in names for p in every if p.name == n]
    if kind == "oblique":
        pairs = oblique_pairs(paths, OBLIQUE_CASES, seed)
    elif kind == "perspective":
        pairs = perspective_pairs(paths, ratios, tilts, seed)
    else:
        pairs = tilted_pairs(paths, ratios, tilts, seed)
    return pairs + (swap(pairs, f"{kind}-swapped") if swapped else [])


def run_variant(name, pair):
    t0 = time.perf_counter()
    r = match(pair.low, pair.high, VARIANTS[name])
    secs = time.perf_counter() - t0
    est = canonical(pair, r.transform if r.matched else None, r.order == "given")
    return {"matched": bool(r.matched), "seconds": secs, "error_px": pair_error(pair, est),
            "view_tilt": r.evidence.view_tilt, "view_of": r.evidence.view_of, "order": r.order,
            "inliers": r.n_inliers, "reason": r.reason,
            # each step run: pass, side, direction, its views' best probe score, matched
            "steps": [[s.view_pass, s.side, str(s.direction), s.probe_best, s.matched]
                      for s in r.search]}


def run_peer(pair):
    t0 = time.perf_counter()
    t, fwd, info = run_sift(pair)
    secs = time.perf_counter() - t0
    est = canonical(pair, t, fwd)
    return {"matched": t is not None, "seconds": secs, "error_px": pair_error(pair, est),
            "inliers": info.get("inliers")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tilts", default=",".join(f"{t:g}" for t in STEEP_TILTS))
    ap.add_argument("--ratios", default="2,4")
    ap.add_argument("--photo-step", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--variants", default="default,tilt-4",
                    help="comma-separated names of VARIANTS: " + ", ".join(VARIANTS))
    ap.add_argument("--swapped", action="store_true")
    ap.add_argument("--kind", choices=("tilted", "perspective", "oblique", "oxford"),
                    default="tilted")
    ap.add_argument("--out", default="bench-out/steep/rows.jsonl")
    args = ap.parse_args()
    cv2.setNumThreads(1)
    tilts = [float(x) for x in args.tilts.split(",")]
    ratios = [float(x) for x in args.ratios.split(",")]
    variants = args.variants.split(",")
    shared = find_shared(None)
    if shared is None:
        sys.exit("../shared is absent: this script needs its photos")
    paths = list_photos(shared)[::args.photo_step]
    pairs = make_pairs(paths, tilts, ratios, args.seed, args.swapped, args.kind, shared)
    if args.kind == "oblique":
        tilts = sorted({t for _, t in OBLIQUE_CASES})
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rows = [json.loads(x) for x in out.read_text().splitlines()] if out.exists() else []
    done = {(r["set"], r["pair"], r["method"]) for r in rows}
    print(f"# {len(pairs)} pairs, {len(paths)} photos, tilts {tilts}, ratios {ratios}, "
          f"load {os.getloadavg()[0]:.1f}", flush=True)
    with out.open("a") as fh:
        for pair in pairs:
            for method in [*variants, "sift"]:
                if (pair.set, pair.name, method) in done:
                    continue
                res = run_peer(pair) if method == "sift" else run_variant(method, pair)
                row = {"set": pair.set, "pair": pair.name, "method": method, "ratio": pair.ratio,
                       "tilt": pair.tilt, **res,
                       "success": bool(is_success(res["error_px"]))}
                row["wrong_claim"] = bool(row["matched"] and not row["success"])
                rows.append(row)
                fh.write(json.dumps(row, default=float) + "\n")
                fh.flush()
                print(f"{pair.set:15s} {pair.name:55s} {method:8s} "
                      f"{'ok ' if row['success'] else ('BAD' if row['wrong_claim'] else '-  ')} "
                      f"{res['seconds']:6.2f} s", flush=True)
    if args.kind == "oxford":  # a row per pair: its error, px, per method
        print("\n| pair | " + " | ".join([*variants, "sift"]) + " |")
        print("|---|" + "---:|" * (len(variants) + 1))
        for p in pairs:
            cells = []
            for m in [*variants, "sift"]:
                r = next((r for r in rows if r["pair"] == p.name and r["method"] == m), None)
                cells.append("-" if r is None else "no match" if not r["matched"] else
                             f"{r['error_px']:.2f} px" + ("" if r["success"] else " (wrong)"))
            print(f"| {p.name} | " + " | ".join(cells) + " |")
        return
    what = "spread" if args.kind == "perspective" else "tilt"
    print(f"\n| set | method | {what} | solved | wrong claims | median s |")
    print("|---|---|---:|---:|---:|---:|")
    for s in sorted({r["set"] for r in rows}):
        for m in [*variants, "sift"]:
            for t in tilts:
                rs = [r for r in rows if r["set"] == s and r["method"] == m and r["tilt"] == t]
                if rs:
                    print(f"| {s} | {m} | {t:g} | {sum(r['success'] for r in rs)}/{len(rs)} | "
                          f"{sum(r['wrong_claim'] for r in rs)} | "
                          f"{np.median([r['seconds'] for r in rs]):.2f} |")


if __name__ == "__main__":
    main()
