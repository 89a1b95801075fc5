"""Points per scale of the detector, adaptive options off and on, at three contrasts (issue 18).

Run: .venv/bin/python scripts/fewpoints_detector.py [--photo data/demo_high.png]
Prints a markdown table (docs/FEWPOINTS.md).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from scalematch.config import Config
from scalematch.imageio import read_grey
from scalematch.lab.datasets import find_shared
from scalematch.lab.synthetic import make_zoom_pair, smooth_scene
from scalematch.stages.detector import HarrisParams, detect, effective_threshold, image_contrast


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--photo", default=str((find_shared() or Path("../shared")) / "data" / "photos"
                                           / "jpegtest_006mp-cathedral.jpg"))
    ap.add_argument("--ratio", type=float, default=8.0)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    photo = read_grey(a.photo)
    pair = make_zoom_pair(photo, a.ratio, np.random.default_rng(a.seed), high_size=(640, 480),
                          source=a.photo)
    scales = Config().scales
    images = {
        "full": pair.high,
        "12-bit as 0-15": pair.high * (4095.0 / 255.0) * (255.0 / 65535.0),
        "32 levels 0-31": np.floor(pair.high / 8.0),
        "smooth synthetic": smooth_scene(),
    }
    configs = {
        "off": HarrisParams(),
        "relative": HarrisParams(contrast_relative=True),
        "relative+budget100": HarrisParams(contrast_relative=True, min_points=100),
    }
    print(f"high image: 640x480 crop of {a.photo} (make_zoom_pair ratio {a.ratio:g}, seed "
          f"{a.seed}); scales {', '.join(f'{s:g}' for s in scales)}\n")
    print("| image | contrast c (grey/px) | noise | option | threshold | points per scale |")
    print("|---|---|---|---|---|---|")
    for name, img in images.items():
        c = image_contrast(img)
        for cname, p in configs.items():
            t0 = time.perf_counter()
            kps = detect(img.astype(np.float32), scales, p)
            dt = time.perf_counter() - t0
            thr = effective_threshold(p, c)
            print(f"| {name} | {c.gradient:.2f} | {c.noise_std:.2f} | {cname} | {thr:.3g} | "
                  f"{' '.join(str(len(k)) for k in kps)} | ({dt * 1000:.0f} ms)")


if __name__ == "__main__":
    main()
