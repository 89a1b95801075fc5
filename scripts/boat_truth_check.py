"""Boat 1->N: how well the published homography and scalematch's fit the images themselves.

Usage: python scripts/boat_truth_check.py   (needs ../shared, or $SCALEMATCH_SHARED)

Its output is docs/results/BOAT.md's table.

For each pair: scalematch's homography and its inliers; the residual of both homographies on
those inliers (median, 90th percentile, low px); the EVALUATION.md error between them; and the
normalised cross-correlation of img1 warped into imgN by each (over the warped footprint).
"""

from __future__ import annotations

import argparse
import os

# one BLAS thread, as the command line uses: read when numpy loads, so set before the imports
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import cv2
import numpy as np

from scalematch import Config, match
from scalematch.geometry import apply
from scalematch.lab.datasets import boat_pairs, find_shared
from scalematch.lab.evaluation import reprojection_error


def ncc(high: np.ndarray, low: np.ndarray, t: np.ndarray) -> float:
    size = (low.shape[1], low.shape[0])
    warped = cv2.warpPerspective(high, t, size, flags=cv2.INTER_AREA)
    mask = cv2.warpPerspective(np.ones_like(high), t, size) > 0.99
    mask = cv2.erode(mask.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    a = warped[mask] - warped[mask].mean()
    b = low[mask] - low[mask].mean()
    return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))


def main() -> None:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    shared = find_shared()
    if shared is None:
        raise SystemExit("../shared not found")
    print("| pair | inliers | residual on inliers, truth: median / 90th pct | ours: median / 90th pct"
          " | error ours vs truth | NCC truth | NCC ours |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for low, high, truth, name in boat_pairs(shared):
        r = match(low, high, Config(model="homography"))
        if not r.matched:
            print(f"| {name} | no match: {r.reason} | | | | | |")
            continue
        src, dst = r.inliers[:, :2], r.inliers[:, 2:]
        rt = np.linalg.norm(apply(truth, src) - dst, axis=1)
        ro = np.linalg.norm(apply(r.transform, src) - dst, axis=1)
        err = reprojection_error(r.transform, truth, high.shape, low.shape)
        print(f"| {name} | {r.n_inliers} | {np.median(rt):.2f} / {np.percentile(rt, 90):.2f} | "
              f"{np.median(ro):.2f} / {np.percentile(ro, 90):.2f} | {err:.2f} | "
              f"{ncc(high, low, truth):.3f} | {ncc(high, low, r.transform):.3f} |")


if __name__ == "__main__":
    main()
