"""The reference a user would write instead of scalematch: OpenCV SIFT, ratio test, RANSAC.

Usage: python scripts/sift_reference.py LOW HIGH

Reads both files as 8-bit grey, detects and describes them with ``cv2.SIFT_create()``, keeps the
brute-force 2-nearest-neighbour matches passing Lowe's ratio test at 0.8 and fits a similarity
with ``cv2.estimateAffinePartial2D`` (RANSAC, 3 px). Prints the 2x3 transform (high px -> low
px) as JSON on stdout, or ``null`` when fewer than 4 inliers support it (exit code 1).
The same recipe as ``scalematch.lab.baselines`` (EVALUATION.md), as one standalone process:
``scripts/speed_bench.py`` times it against ``scalematch LOW HIGH``.
"""

import argparse
import json
import sys

import cv2
import numpy as np


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("low", help="the low-resolution image")
    ap.add_argument("high", help="the high-resolution image")
    args = ap.parse_args()
    low = cv2.imread(args.low, cv2.IMREAD_GRAYSCALE)
    high = cv2.imread(args.high, cv2.IMREAD_GRAYSCALE)
    if low is None or high is None:
        sys.exit("cannot read the images")
    cv2.setRNGSeed(0)
    sift = cv2.SIFT_create()
    kp_low, d_low = sift.detectAndCompute(low, None)
    kp_high, d_high = sift.detectAndCompute(high, None)
    t = None
    if d_low is not None and d_high is not None and len(kp_low) >= 2:
        knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(d_high, d_low, k=2)
        good = [m[0] for m in knn if len(m) == 2 and m[0].distance < 0.8 * m[1].distance]
        if len(good) >= 4:
            src = np.float32([kp_high[m.queryIdx].pt for m in good])
            dst = np.float32([kp_low[m.trainIdx].pt for m in good])
            t, mask = cv2.estimateAffinePartial2D(src, dst, method=cv2.RANSAC,
                                                  ransacReprojThreshold=3.0)
            if t is not None and int(mask.sum()) < 4:
                t = None
    print(json.dumps(None if t is None else np.asarray(t).tolist()))
    return 0 if t is not None else 1


if __name__ == "__main__":
    sys.exit(main())
