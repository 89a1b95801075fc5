"""Issue 18 figures on zoom pairs cut from ../shared/data/photos: guided growth from 5 true
inliers vs a wrong hypothesis, and the pixel check on true / wrong / unrelated placements.

Run: .venv/bin/python scripts/fewpoints_measure.py --photos 7 --ratios 6,8,10 --seed 0
(7 photos x 3 ratios = 21 pairs; every other photo of the sorted list; one process, ~1 min).
Prints per-pair lines and the summary tables of docs/FEWPOINTS.md.
"""
from __future__ import annotations

import argparse
import glob
import math
import time

import numpy as np

from scalematch.geometry import apply, compose, similarity_matrix
from scalematch.lab.synthetic import make_unrelated_pair, pair_rng, pairs_from_photos
from scalematch.imageio import read_grey
from scalematch.stages.descriptors import describe_gradients
from scalematch.stages.detector import HarrisParams, detect_on_level
from scalematch.stages.estimator import estimate
from scalematch.stages.guided import grow
from scalematch.stages.pixelcheck import pixel_check
from scalematch.stages.scalespace import Level, scale_space

PHOTOS = "/work/shared/data/photos"
SCALES = (1.0, 1.26, 1.587, 2.0, 2.52, 3.175, 4.0, 5.04, 6.35, 8.0, 10.079, 12.699)


def features(high, low, s):
    lv = next(scale_space(high, (s,)))
    hk = detect_on_level(lv, HarrisParams())
    ll = Level(1.0, 1.0, 0.0, low)
    lk = detect_on_level(ll, HarrisParams(max_points=12000))
    return describe_gradients(lv, hk.xy), describe_gradients(ll, lk.xy)


def placed_elsewhere(t, high_shape, low_shape, rng):
    """The truth's ratio, a random angle, its footprint centred at a random point of low that
    is at least one footprint away from the true centre."""
    h, w = high_shape
    c_true = apply(t, [[(w - 1) / 2, (h - 1) / 2]])[0]
    ratio = math.sqrt(1 / abs(np.linalg.det(t[:2, :2])))
    size = max(w, h) / ratio
    for _ in range(100):
        c = rng.uniform([0, 0], [low_shape[1], low_shape[0]])
        if np.linalg.norm(c - c_true) > size:
            break
    lin = similarity_matrix(1 / ratio, float(rng.uniform(-180, 180)))
    m = lin.copy()
    m[:, 2] = c - apply(lin, [[(w - 1) / 2, (h - 1) / 2]])[0]
    return m


def pct(v, qs=(0, 5, 50, 95, 100)):
    v = np.asarray([x for x in v if np.isfinite(x)])
    return " / ".join(f"{np.percentile(v, q):.3f}" for q in qs) if v.size else "-"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--photos", type=int, default=7)
    ap.add_argument("--ratios", default="6,8,10")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--nulls", type=int, default=3, help="random placements per unrelated pair")
    a = ap.parse_args()
    ratios = [float(r) for r in a.ratios.split(",")]
    paths = sorted(glob.glob(f"{PHOTOS}/*.[jJ][pP]*"))[::2][: a.photos]
    rows = {"true": [], "wrong": [], "null": []}
    grown = {"true": [], "wrong": []}
    times = []
    t_start = time.perf_counter()
    for pair in pairs_from_photos(paths, ratios, seed=a.seed):
        rng = np.random.default_rng([a.seed, int(pair.ratio * 1000), len(rows["true"])])
        s = min(SCALES, key=lambda v: abs(math.log(v / pair.ratio)))
        hd, ld = features(pair.high, pair.low, s)
        # 5 true inliers: high points with a low point within 1.5 px of their true position
        pred = apply(pair.truth, hd.xy)
        d = np.linalg.norm(pred[:, None] - ld.xy[None], axis=2) if len(hd) and len(ld) else None
        g_true = g_wrong = None
        wrong = placed_elsewhere(pair.truth, pair.high.shape, pair.low.shape, rng)
        if d is not None:
            j = d.argmin(1)
            idx = np.nonzero(d[np.arange(len(j)), j] <= 1.5)[0]
            if idx.size >= 5:
                pick = rng.choice(idx, 5, replace=False)
                est = estimate("similarity", hd.xy[pick], ld.xy[j[pick]])
                if est.transform is not None:
                    g_true = grow(est.transform, hd, ld)
            g_wrong = grow(wrong, hd, ld)
        t0 = time.perf_counter()
        ct = pixel_check(pair.low, pair.high, pair.truth)
        times.append(time.perf_counter() - t0)
        cw = pixel_check(pair.low, pair.high, wrong)
        rows["true"].append(ct)
        rows["wrong"].append(cw)
        gt = g_true.counts if g_true else "-"
        gw = g_wrong.counts if g_wrong else "-"
        if g_true:
            grown["true"].append(g_true.n_inliers)
        if g_wrong:
            grown["wrong"].append(g_wrong.n_inliers)
        print(f"{pair.source[:24]:24s} r={pair.ratio:g} s={s:g} high pts {len(hd)} | grow true5 "
              f"{gt} chance {g_true.chance if g_true else float('nan'):.1f} | wrong {gw} | "
              f"pix true ncc {ct.ncc:.3f} margin {ct.margin:.3f} z {ct.z:.1f} | wrong ncc "
              f"{cw.ncc:.3f} margin {cw.margin:.3f} z {cw.z:.1f} {cw.reason}", flush=True)
    # null: the high image of one photo on the low image of another, random placements
    photos = {p: read_grey(p) for p in paths}
    names = list(photos)
    for k, pl in enumerate(names):
        ph = names[(k + 1) % len(names)]
        for r in ratios:
            rng = pair_rng(a.seed + 1, f"{pl}|{ph}", r)
            up = make_unrelated_pair(photos[pl], photos[ph], r, rng)
            for _ in range(a.nulls):
                t = placed_elsewhere(similarity_matrix(1 / r, 0.0), up.high.shape, up.low.shape,
                                     rng)
                rows["null"].append(pixel_check(up.low, up.high, t))
    print(f"\n{len(rows['true'])} true pairs, {len(rows['null'])} null placements, "
          f"{time.perf_counter() - t_start:.0f} s; pixel_check median {np.median(times) * 1000:.1f}"
          f" ms, max {max(times) * 1000:.1f} ms\n")
    print("| placements | n | undecided | ncc min / 5% / median / 95% / max | margin min / 5% / "
          "median / 95% / max | z min / 5% / median / 95% / max |")
    print("|---|---|---|---|---|---|")
    for name, cs in rows.items():
        und = sum(not c.decided for c in cs)
        print(f"| {name} | {len(cs)} | {und} | {pct([c.ncc for c in cs])} | "
              f"{pct([c.margin for c in cs])} | {pct([c.z for c in cs])} |")
    print(f"\ngrowth: true 5 -> min/median/max {min(grown['true'])}/"
          f"{int(np.median(grown['true']))}/{max(grown['true'])} inliers over {len(grown['true'])}"
          f" pairs; wrong -> min/median/max {min(grown['wrong'])}/"
          f"{int(np.median(grown['wrong']))}/{max(grown['wrong'])} over {len(grown['wrong'])}")


if __name__ == "__main__":
    main()
