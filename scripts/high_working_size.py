"""A 24 MP high image matched at full size and at its working size, at several ratios (issue 12).

Usage: python scripts/high_working_size.py [--ratios 1.5,2,3,5,10] [--seed 0] [--sides full,2048]

For each ratio r: the large pair of ``speed_bench.py`` (the largest photo of ../shared enlarged
to 9000x6000, its centre 6000x4000 the high image, exact truth, EVALUATION.md) zoomed out by r,
in a low window of 1800x1200 px or the footprint's size plus a margin.
Then ``scalematch.match`` in this process with ``high_max_side=None`` (full size, as before)
and with the default (2048 px), alternately. Prints one Markdown row per ratio and setting:
seconds, error (low px), the ratio found and the order.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Tuple

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

from scalematch import Config, match  # noqa: E402
from scalematch.lab.datasets import find_shared, list_photos  # noqa: E402
from scalematch.lab.evaluation import reprojection_error  # noqa: E402
from speed_bench import LARGE_HIGH, LARGE_SCENE, enlarged_scene, large_pair  # noqa: E402

LOW_MIN_WINDOW = (1800, 1200)  #: the low window, px, unless the footprint needs more
MARGIN = 1.3  #: low window / footprint side when the footprint is larger than LOW_MIN_WINDOW


def low_window(ratio: float) -> Tuple[int, int]:
    """A low window holding the high image's footprint at any angle."""
    side = int(np.ceil(np.hypot(*LARGE_HIGH) / ratio * MARGIN))
    return max(LOW_MIN_WINDOW[0], side), max(LOW_MIN_WINDOW[1], side)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ratios", default="1.5,2,3,5,10")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sides", default="full,2048",
                    help="working sizes to compare, px ('full': the high image at full size)")
    a = ap.parse_args()
    shared = find_shared()
    if shared is None:
        sys.exit("../shared is absent")
    photo = max(list_photos(shared), key=lambda p: p.stat().st_size)
    scene = enlarged_scene(photo)
    print(f"{photo.name} enlarged to {LARGE_SCENE[0]}x{LARGE_SCENE[1]}, high "
          f"{LARGE_HIGH[0]}x{LARGE_HIGH[1]}, seed "
          f"{a.seed}, load average {os.getloadavg()[0]:.1f}\n")
    print("| ratio | low px | high image matched at | seconds | error px | ratio found | order |")
    print("|---|---|---|---:|---:|---:|---|")
    default = Config().high_max_side
    settings = tuple(
        ("full size", Config(high_max_side=None)) if side == "full" else
        (f"{side} px{' (default)' if int(side) == default else ''}",
         Config(low_max_side=int(side), high_max_side=int(side)))
        for side in a.sides.split(","))
    for k, ratio in enumerate(float(r) for r in a.ratios.split(",")):
        p = large_pair(scene, a.seed, ratio, low_window(ratio), photo.name)
        for name, config in (settings if k % 2 == 0 else settings[::-1]):
            t0 = time.perf_counter()
            r = match(p.low, p.high, config)
            secs = time.perf_counter() - t0
            err = reprojection_error(r.transform if r.matched else None, p.truth, p.high.shape,
                                     p.low.shape)
            print(f"| {ratio:g} | {p.low.shape[1]}x{p.low.shape[0]} | {name} | {secs:.2f} | "
                  f"{err:.3f} | {r.resolution_ratio:.3f} | {r.order} |", flush=True)
    print(f"\nload average at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
