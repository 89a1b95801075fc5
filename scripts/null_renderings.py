"""How firm is a "no" on the hardest nulls? The same null pairs rendered from two decodings.

Usage: python scripts/null_renderings.py [--photos strecha,sceaux] [--ratios 2,3,4,6,8,10,12,16]
       [--jobs 2] [--out FILE.jsonl]

``scalematch lab nulls`` makes its same-photo pairs (two disjoint halves of one photo: a low
image from one, a high crop from the other) from the photo as ``imageio.read_grey`` decodes it.
OpenCV's own grey decoding (``cv2.IMREAD_GRAYSCALE``) differs from it by a fraction of a grey
level on average: the same pair, as another camera pipeline or another library would give it.
A decision whose "no" holds only for one of the two sits on a knife's edge. Each pair of
``--photos`` (file names containing any of the comma-separated words; default: the photos of
buildings, whose repeated windows are the hardest nulls) at each of ``--ratios`` is made both
ways (the lab's spec, seed 0) and matched by the default ``Config`` in both orders. Prints every
run that either rendering claims, or whose outcome differs between them, with the figures the
decision read; rows go to ``--out`` (bench-out/ is not committed). Needs ../shared.
"""

from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scalematch.lab.datasets import require_shared  # noqa: E402

#: the photos, where the lab finds them ($SCALEMATCH_SHARED, else ../shared)
PHOTOS = require_shared() / "data" / "photos"
BUILDINGS = "strecha,sceaux,360school,berlin,bus,cathedral"


def decoded(name: str, how: str):
    """The photo ``name`` as (H, W) float32 grey, decoded ``how`` ("lab" or "opencv")."""
    import cv2
    import numpy as np

    from scalematch.imageio import read_grey

    if how == "lab":
        return read_grey(PHOTOS / name)
    return cv2.imread(str(PHOTOS / name), cv2.IMREAD_GRAYSCALE).astype(np.float32)


def run(job):
    """Both renderings of one same-photo null pair, both orders: a row per run."""
    import cv2
    import numpy as np

    from scalematch.config import Config
    from scalematch.lab import nulls
    from scalematch.pipeline import match

    cv2.setNumThreads(1)
    photo, ratio = job
    spec = nulls.NullSpec("same-photo", photo, photo, float(ratio), 0)
    rows = []
    for how in ("lab", "opencv"):
        pair = nulls.make_pair(spec, lambda n: decoded(n, how))
        low, high = pair.low.astype(np.float32), pair.high.astype(np.float32)
        for order in ("given", "swapped"):
            a, b = (low, high) if order == "given" else (high, low)
            r = match(a, b, Config())
            e = r.evidence
            rows.append(dict(photo=photo, ratio=ratio, rendering=how, order=order,
                             matched=bool(r.matched), model=r.model, inliers=int(r.n_inliers),
                             reason=r.reason or "", log10_nfa=float(e.log10_nfa),
                             unique_ratio=float(e.unique_ratio),
                             windows_agreeing=float(e.windows_agreeing),
                             windows_elsewhere=float(e.windows_elsewhere)))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photos", default=BUILDINGS, help="words a photo's file name contains")
    ap.add_argument("--ratios", default="2,3,4,6,8,10,12,16")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default="bench-out/null-renderings.jsonl")
    args = ap.parse_args()
    words = [w for w in args.photos.split(",") if w]
    photos = sorted(p.name for p in PHOTOS.iterdir()
                    if p.suffix.lower() in (".jpg", ".png") and any(w in p.name for w in words))
    jobs = [(p, float(r)) for p in photos for r in args.ratios.split(",")]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    claims = {"lab": 0, "opencv": 0}
    runs = 0
    with ProcessPoolExecutor(args.jobs) as pool, out.open("w") as f:
        for rows in pool.map(run, jobs):
            for row in rows:
                f.write(json.dumps(row) + "\n")
            runs += 2  # both orders, in each rendering
            by = {(r["rendering"], r["order"]): r for r in rows}
            for order in ("given", "swapped"):
                lab, cv = by[("lab", order)], by[("opencv", order)]
                claims["lab"] += lab["matched"]
                claims["opencv"] += cv["matched"]
                if lab["matched"] or cv["matched"] or lab["reason"][:20] != cv["reason"][:20]:
                    for r in (lab, cv):
                        print(f"{r['photo']} x{r['ratio']:g} {order} {r['rendering']}: "
                              f"{'CLAIMED ' + r['model'] if r['matched'] else 'no'}, "
                              f"{r['inliers']} inliers, log10 NFA {r['log10_nfa']:.1f}, "
                              f"uniqueness {r['unique_ratio']:.2f}, windows "
                              f"{r['windows_agreeing']:.2f} against {r['windows_elsewhere']:.2f}"
                              f"{'' if r['matched'] else '; ' + r['reason'][:70]}", flush=True)
    print(f"{runs} runs a rendering ({len(photos)} photos): claims, the lab's rendering "
          f"{claims['lab']}, OpenCV's {claims['opencv']}")


if __name__ == "__main__":
    main()
