"""Peak memory and time of the scale-adapted Harris detector on a 6000x4000 image (issue 2).

Usage: python scripts/detector_memory.py [PHOTO]   (default: a photo from ../shared)

The photo is enlarged (bicubic) to 6000x4000 and converted to float32 grey; the detector runs at
the paper's eight scales. Peak memory is the process's peak resident set size (VmHWM, reset
after loading the image) minus its size before detection, on Linux.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import scalematch  # noqa: F401  (first: sets the BLAS threads before numpy loads)
import cv2
import numpy as np

from scalematch.stages.detector import PAPER_SCALES, detect

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT.parent / "shared" / "data" / "photos" / "jpegtest_012mp-bus.jpg"


def _status(key: str) -> float:
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def main() -> None:
    path = Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        sys.exit(f"cannot read {path}")
    big = cv2.resize(img, (6000, 4000), interpolation=cv2.INTER_CUBIC).astype(np.float32)
    del img
    with open("/proc/self/clear_refs", "w") as fh:  # reset the peak mark
        fh.write("5")
    before = _status("VmRSS")
    t = time.perf_counter()
    kps = detect(big, PAPER_SCALES)
    seconds = time.perf_counter() - t
    peak = _status("VmHWM")
    image_mb = big.nbytes / 2 ** 20
    print(f"{path.name} enlarged to 6000x4000 (float32 image {image_mb:.0f} MB)")
    print(f"detect at scales {PAPER_SCALES}: {seconds:.2f} s")
    print(f"peak memory above the loaded image: {peak - before:.0f} MB "
          f"({(peak - before) / image_mb:.1f} image-sized float copies)")
    print("points per scale:", [len(k) for k in kps])


if __name__ == "__main__":
    main()
