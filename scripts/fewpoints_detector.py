"""Points per scale of the detector, adaptive options off and on, at three contrasts (issue 18).

Run: .venv/bin/python scripts/fewpoints_detector.py [--photo data/demo_high.png]
Prints a markdown table (docs/FEWPOINTS.md).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from scalematch.config import Config
from scalematch.imageio import read_grey
from scalematch.lab.synthetic import make_zoom_pair
from scalematch.stages.detector import HarrisParams, detect, effective_threshold, image_contrast


def smooth_scene(shape=(480, 640), seed=0) -> np.ndarray:
    """Wide soft stripes and blobs (a smooth facade): the scene that starves the detector."""
    rng = np.random.default_rng(seed)
    h, w = shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    img = 128 + 50 * np.tanh(3 * np.sin(2 * np.pi * (x * 0.9 + y * 0.3) / 160.0))
    for _ in range(6):
        cx, cy, r = rng.uniform(0, w), rng.uniform(0, h), rng.uniform(30, 90)
        img += rng.uniform(-40, 40) * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * r * r))
    return np.clip(img + rng.normal(0, 1.0, img.shape), 0, 255).astype(np.float32)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--photo", default="/work/shared/data/photos/jpegtest_006mp-cathedral.jpg")
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
