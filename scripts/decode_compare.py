"""OpenCV or Pillow to decode PNG and JPEG: time and peak memory of each, on one large photo.

Usage: python scripts/decode_compare.py [--photo PATH] [--repeats 7]

A benchmark, not a test. The photo (default: ../shared/data/photos/snowpeak_IMG_2282.JPG,
4608x3456, 16 MP) is read as a JPEG and, written again as a PNG (OpenCV's default
compression), as a PNG. Each way of decoding the bytes already in memory is timed
alternately in one run (every way once per round, the order turned by one each round, so that
a change of machine load falls on all of them), and its peak memory is measured in a process
of its own: the child's high-water mark of resident memory (``VmHWM`` of /proc/self/status,
which, unlike ``ru_maxrss``, does not count what the parent held when it forked) above what it
held after reading the file and importing both libraries, MB.

The ways, as ``scalematch.imageio`` would use each:

* full decode: ``cv2.imdecode`` (``IMREAD_ANYDEPTH | IMREAD_ANYCOLOR |
  IMREAD_IGNORE_ORIENTATION``: BGR) against ``PIL.Image.open(...).load()`` and
  ``np.asarray`` (RGB);
* full decode and grey: the above then ``greylevels.to_grey`` (float32 BT.601) for OpenCV, and
  for Pillow ``convert("L")`` (8-bit BT.601, rounded) then float32; and, to tell the decoder
  from the conversion, OpenCV's decode then ``cv2.cvtColor`` on the 8-bit image (rounded,
  as Pillow's) then float32 (``cv2_grey8``);
* reduced JPEG decode, 1/2, 1/4 and 1/8 a side: ``IMREAD_REDUCED_GRAYSCALE_f`` against
  ``Image.draft("L", (w / f, h / f))`` (libjpeg's DCT scaling in both), with how far the two
  images differ (rms grey levels);
* the PNG chunks' CRCs checked in Python (``zlib.crc32`` over every chunk): what Pillow,
  which does not check the image data's CRC, would need to refuse a damaged one as libpng does.

Ratios are the median time of each way over the median of OpenCV's way of the same task. The
figures are in docs/design/SPEED.md, "Decoding: OpenCV, not Pillow".
"""

from __future__ import annotations

import argparse
import io
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path
from typing import Callable, Dict, List, Tuple

import cv2
import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scalematch.greylevels import to_grey  # noqa: E402
from scalematch.imageio import REDUCED_FLAGS  # noqa: E402
from scalematch.lab.datasets import find_shared  # noqa: E402

#: The photo of docs/design/SPEED.md's reduced decode, 4608x3456 (../shared or $SCALEMATCH_SHARED).
PHOTO = (find_shared() or ROOT.parent / "shared") / "data" / "photos" / "snowpeak_IMG_2282.JPG"
FULL = cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR | cv2.IMREAD_IGNORE_ORIENTATION


def cv2_full(data: bytes, _f: int = 1) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(data, np.uint8), FULL)


def pil_full(data: bytes, _f: int = 1) -> np.ndarray:
    with Image.open(io.BytesIO(data)) as im:
        im.load()
        return np.asarray(im)


def cv2_grey(data: bytes, _f: int = 1) -> np.ndarray:
    return to_grey(cv2_full(data))


def cv2_grey8(data: bytes, _f: int = 1) -> np.ndarray:
    return cv2.cvtColor(cv2_full(data), cv2.COLOR_BGR2GRAY).astype(np.float32)


def pil_grey(data: bytes, _f: int = 1) -> np.ndarray:
    with Image.open(io.BytesIO(data)) as im:
        return np.asarray(im.convert("L"), dtype=np.float32)


def cv2_reduced(data: bytes, f: int) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(data, np.uint8), REDUCED_FLAGS[f])


def pil_reduced(data: bytes, f: int) -> np.ndarray:
    with Image.open(io.BytesIO(data)) as im:
        w, h = im.size
        im.draft("L", (-(-w // f), -(-h // f)))
        im.load()
        return np.asarray(im)


def png_crcs(data: bytes, _f: int = 1) -> bool:
    """Whether every chunk's CRC is right."""
    pos, ok = 8, True
    while pos + 12 <= len(data):
        n = int.from_bytes(data[pos:pos + 4], "big")
        ok &= zlib.crc32(data[pos + 4:pos + 8 + n]) == int.from_bytes(
            data[pos + 8 + n:pos + 12 + n], "big")
        if data[pos + 4:pos + 8] == b"IEND":
            break
        pos += 12 + n
    return ok


WAYS: Dict[str, Callable[[bytes, int], object]] = {
    "cv2_full": cv2_full, "pil_full": pil_full, "cv2_grey": cv2_grey, "cv2_grey8": cv2_grey8, "pil_grey": pil_grey,
    "cv2_reduced": cv2_reduced, "pil_reduced": pil_reduced, "png_crcs": png_crcs}

#: (format, task, way, factor, the way it is compared with)
ROWS: List[Tuple[str, str, str, int, str]] = (
    [(fmt, task, f"{lib}_{kind}", 1, f"cv2_{kind}")
     for fmt in ("jpg", "png") for task, kind in (("decode", "full"), ("decode + grey", "grey"))
     for lib in ("cv2", "pil")]
    + [(fmt, "decode + grey", "cv2_grey8", 1, "cv2_grey") for fmt in ("jpg", "png")]
    + [("jpg", f"reduced 1/{f} grey", f"{lib}_reduced", f, "cv2_reduced")
       for f in (2, 4, 8) for lib in ("cv2", "pil")]
    + [("png", "CRCs in Python", "png_crcs", 1, "cv2_full")])

#: The child measuring one way's peak memory.
CHILD = """
import json, sys
sys.path.insert(0, {scripts!r})
import decode_compare as d
data = open(sys.argv[1], "rb").read()
before = d.hwm_kb()
out = d.WAYS[sys.argv[2]](data, int(sys.argv[3]))
print(json.dumps({{"before_kb": before, "after_kb": d.hwm_kb(),
                  "nbytes": getattr(out, "nbytes", 0)}}))
"""


def hwm_kb() -> int:
    """The process's peak resident memory so far, kB (Linux)."""
    with open("/proc/self/status") as fh:
        return int(next(line for line in fh if line.startswith("VmHWM:")).split()[1])


def peak_mb(path: Path, way: str, f: int) -> Tuple[float, float]:
    """(peak memory above the child's before decoding, MB; the result's own size, MB)."""
    code = CHILD.format(scripts=str(ROOT / "scripts"))
    out = subprocess.run([sys.executable, "-c", code, str(path), way, str(f)],
                         capture_output=True, text=True, check=True).stdout
    row = json.loads(out)
    return (row["after_kb"] - row["before_kb"]) / 1024, row["nbytes"] / 2**20


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photo", type=Path, default=PHOTO)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        paths = {"jpg": args.photo, "png": Path(tmp) / "photo.png"}
        cv2.imwrite(str(paths["png"]), cv2.imread(str(args.photo), FULL))
        data = {fmt: p.read_bytes() for fmt, p in paths.items()}
        print(f"{args.photo.name}: JPEG {len(data['jpg']) / 1e6:.1f} MB, PNG "
              f"{len(data['png']) / 1e6:.1f} MB; load {os.getloadavg()[0]:.2f}")
        for f in (2, 4, 8):
            a, b = (cv2_reduced(data["jpg"], f).astype(np.float32),
                    pil_reduced(data["jpg"], f).astype(np.float32))
            rms = float(np.sqrt(np.mean((a - b) ** 2))) if a.shape == b.shape else float("nan")
            print(f"reduced 1/{f}: OpenCV {a.shape}, Pillow {b.shape}, rms {rms:.3f} grey levels")
        a, b = cv2_grey(data["jpg"]), pil_grey(data["jpg"])
        print(f"grey of the full JPEG: rms {float(np.sqrt(np.mean((a - b) ** 2))):.3f} levels")
        times: Dict[Tuple[str, str, int], List[float]] = {}
        keys = sorted({(fmt, way, f) for fmt, _, way, f, _ in ROWS})
        for r in range(args.repeats):
            for k in keys[r % len(keys):] + keys[:r % len(keys)]:
                fmt, way, f = k
                t0 = time.perf_counter()
                WAYS[way](data[fmt], f)
                times.setdefault(k, []).append(time.perf_counter() - t0)
        print(f"load after {os.getloadavg()[0]:.2f}\n")
        print("| format | task | method | median s | time ratio | peak MB above start | "
              "result MB |")
        print("|---|---|---|---|---|---|---|")
        for fmt, task, way, f, base in ROWS:
            med = statistics.median(times[(fmt, way, f)])
            ratio = med / statistics.median(times[(fmt, base, f)])
            peak, result = peak_mb(paths[fmt], way, f)
            print(f"| {fmt} | {task} | {way} | {med:.3f} | {ratio:.2f} | {peak:.0f} | "
                  f"{result:.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
