"""Every claim on true pairs with its evidence: which claims are right, which wrong, and why.

Usage: python scripts/margin_study.py [--sets zoom,hard,oxford,tilted,steep] [--photos N]
       [--out FILE.jsonl]

Pairs: the benchmark's zoom pairs (the photos of ../shared, ratios 2-16, the most textured
crop), the hard set (the least textured crop), the Oxford pairs both ways (homography), the
real-pairs tilted pairs (every 3rd photo, ratios 2 and 4, t 1.41-4) and steep ones (t 6 and 8).
scalematch runs with ``Config()``; one JSON row per pair: success (grid error < 3 px), the
claim and its Evidence (``final_margin``, ``unique_ratio``, ...), appended to ``--out`` and
resumed from it. Then a table per set: pairs, right claims, wrong claims, and the smallest
final margin of the right ones (docs/design/DECISION.md). Needs ../shared.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

import cv2  # noqa: E402

from scalematch import Config, match  # noqa: E402
from scalematch.geometry import as_matrix3, invert  # noqa: E402
from scalematch.lab.datasets import find_shared, list_photos  # noqa: E402
from scalematch.lab.evaluation import is_success, reprojection_error  # noqa: E402
from scalematch.lab.realpairs import (STEEP_TILTS, canonical, oxford_pairs,  # noqa: E402
                                      pair_error)
from scalematch.lab.synthetic import TILTS, pairs_from_photos  # noqa: E402
from steep_views import make_pairs  # noqa: E402

RATIOS = (2.0, 3.0, 4.0, 6.0, 8.0, 10.0, 12.0, 16.0)


def jobs(sets, photos):
    if "zoom" in sets or "hard" in sets:
        for name, pick in (("zoom", "most"), ("hard", "least")):
            if name in sets:
                for p in pairs_from_photos(photos, RATIOS, 0, pick=pick):
                    yield name, f"{p.source} x{p.ratio:g}", p.low, p.high, \
                        lambda t, fwd, p=p: reprojection_error(t if fwd else invert(t), p.truth,
                                                               p.high.shape, p.low.shape)
    if "oxford" in sets:  # boat, graf, wall both ways, the homography model as the peers
        for pair in oxford_pairs(find_shared(None)):
            yield "oxford", pair.name, pair.low, pair.high, \
                lambda t, fwd, pair=pair: pair_error(pair, canonical(pair, t, fwd))
    for name, tilts in (("tilted", TILTS), ("steep", STEEP_TILTS)):
        if name in sets:
            for pair in make_pairs(photos[::3], tilts, (2.0, 4.0), 0, False):
                yield name, pair.name, pair.low, pair.high, \
                    lambda t, fwd, pair=pair: pair_error(pair, canonical(pair, t, fwd))


def summary(rows) -> str:
    """A Markdown row per set: pairs, right and wrong claims, the right claims' least margin."""
    out = ["| set | pairs | right claims | wrong claims | least final margin of a right claim |",
           "|---|---:|---:|---:|---:|"]
    for name in dict.fromkeys(r["set"] for r in rows):
        rs = [r for r in rows if r["set"] == name]
        right = [r for r in rs if r["success"]]
        margins = [r["final_margin"] for r in right if r.get("final_margin") is not None]
        out.append(f"| {name} | {len(rs)} | {len(right)} | "
                   f"{sum(r['matched'] and not r['success'] for r in rs)} | "
                   f"{min(margins):.3f} |" if margins else
                   f"| {name} | {len(rs)} | {len(right)} | "
                   f"{sum(r['matched'] and not r['success'] for r in rs)} | - |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", default="zoom,hard,oxford,tilted,steep")
    ap.add_argument("--photos", type=int, default=None, help="only the first N photos")
    ap.add_argument("--out", default="bench-out/margins/rows.jsonl")
    args = ap.parse_args()
    cv2.setNumThreads(1)
    shared = find_shared(None)
    if shared is None:
        sys.exit("../shared is absent: this script needs its photos")
    photos = list_photos(shared)[:args.photos]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    done = {(r["set"], r["pair"]) for r in map(json.loads, out.read_text().splitlines())} \
        if out.exists() else set()
    with out.open("a") as fh:
        for name, pair, low, high, error in jobs(args.sets.split(","), photos):
            if (name, pair) in done:
                continue
            t0 = time.perf_counter()
            r = match(low, high, Config(model="homography") if name == "oxford" else Config())
            secs = time.perf_counter() - t0
            err = float("nan")
            if r.matched:
                err = error(as_matrix3(r.transform), r.order == "given")
            row = {"set": name, "pair": pair, "matched": r.matched, "order": r.order,
                   "model": r.model, "error_px": err, "success": bool(is_success(err)),
                   "seconds": secs, **{k: v for k, v in dataclasses.asdict(r.evidence).items()
                                       if isinstance(v, (int, float, str, bool, type(None)))}}
            fh.write(json.dumps(row, default=float) + "\n")
            fh.flush()
    print(summary([json.loads(x) for x in out.read_text().splitlines()]))


if __name__ == "__main__":
    main()
