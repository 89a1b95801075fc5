"""Make the demo pair data/demo_low.png and data/demo_high.png from data/raccoon.jpg.

high: a 480 x 360 crop of the raccoon's face at full resolution (x 420..899, y 150..509), grey
      (BT.601 luma; a monochrome telephoto, and it keeps the two files under 400 KB).
low:  the whole photo turned by 25 degrees and shrunk by 3 with ``zoom_warp`` (the camera blur
      of a real shrink included), then a mild gain (x 0.9 + 12 grey levels) and sensor noise
      (std 2 grey levels, seed 0) inside the photo's footprint.

The truth transform (high px -> low px, OpenCV pixel convention) is printed; it is recorded in
data/SOURCES.md. The script is deterministic: the shipped files are what it writes.

Usage: python scripts/make_demo.py [--out-dir data]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # runs from a checkout without installing

from scalematch.geometry import compose  # noqa: E402
from scalematch.lab.synthetic import zoom_warp  # noqa: E402
RATIO = 3.0  #: resolution ratio: high-res px per low-res px
ANGLE_DEG = 25.0  #: rotation of low relative to high (zoom_warp's convention)
CROP = (420, 150, 480, 360)  #: x0, y0, width, height of the high-resolution crop, photo px
GAIN, OFFSET, NOISE = 0.9, 12.0, 2.0  #: grey-level change and noise std of the low image
SEED = 0


def make(photo: np.ndarray):
    """(low, high, truth 2x3) from the colour photo."""
    x0, y0, w, h = CROP
    high = cv2.cvtColor(photo[y0:y0 + h, x0:x0 + w], cv2.COLOR_BGR2GRAY)
    low, a = zoom_warp(photo, RATIO, ANGLE_DEG)
    inside, _ = zoom_warp(np.full(photo.shape[:2], 255, np.uint8), RATIO, ANGLE_DEG,
                          interpolation=cv2.INTER_NEAREST)
    rng = np.random.default_rng(SEED)
    noisy = low.astype(np.float64) * GAIN + OFFSET + rng.normal(0.0, NOISE, low.shape)
    low = np.where(inside[..., None] > 0, np.clip(np.round(noisy), 0, 255), 0).astype(np.uint8)
    truth = compose(a, np.array([[1.0, 0.0, x0], [0.0, 1.0, y0]]))  # high -> photo -> low
    return low, high, truth


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out-dir", type=Path, default=ROOT / "data",
                    help="where to write demo_low.png and demo_high.png (default: data/)")
    args = ap.parse_args()
    photo = cv2.imread(str(ROOT / "data" / "raccoon.jpg"), cv2.IMREAD_COLOR)
    low, high, truth = make(photo)
    opts = [cv2.IMWRITE_PNG_COMPRESSION, 9]
    args.out_dir.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.out_dir / "demo_low.png"), low, opts)
    cv2.imwrite(str(args.out_dir / "demo_high.png"), high, opts)
    print(f"low {low.shape[1]}x{low.shape[0]}, high {high.shape[1]}x{high.shape[0]}")
    print("truth (high px -> low px):", [[round(float(v), 4) for v in row] for row in truth])


if __name__ == "__main__":
    main()
