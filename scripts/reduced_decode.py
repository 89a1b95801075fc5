"""Large JPEGs decoded at a reduced size against decoded in full: the same answers? (issue 16)

Usage: python scripts/reduced_decode.py [--ratios 2,3,6] [--seed 0]

Every JPEG of ../shared/data/photos that the command line decodes at a reduced size (its longer
side at least twice the working size of 2048 px, less ``imageio.REDUCED_SLACK``: 20 photos of
4000 to 5376 px, decoded at half size) gives pairs written as files, with exact truth (OpenCV
pixel centres, :func:`scalematch.geometry.resize_map`):

* ``high``: the JPEG is the high image; the low one is the photo shrunk by r (INTER_AREA, PNG),
  for each ratio r of ``--ratios``;
* ``low``: the JPEG is the low image; the high one is a 1024x768 region of the photo, at a
  seeded place, enlarged 2x (INTER_CUBIC, PNG): ratio 2.

Each pair is read and matched twice in this process, alternately: as before (``read_image``,
the whole file decoded) and as the command line now reads it (``working.read_pair``, the answer given
in the files' pixels through ``decoded_factors``). Prints a Markdown row per pair: the seconds
(read + match), the error against the truth (mean over a grid, low px, EVALUATION.md) and the
gap between the two answers (low px); then the medians.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scalematch import Config, match  # noqa: E402
from scalematch.geometry import apply, as_matrix3, invert, resize_map  # noqa: E402
from scalematch.imageio import read_bytes, read_image, reduction, to_grey  # noqa: E402
from scalematch.lab.datasets import find_shared, list_photos  # noqa: E402
from scalematch.lab.evaluation import reprojection_error  # noqa: E402
from scalematch.stages.decision import mean_transfer_gap  # noqa: E402
from scalematch.working import decode_sides, read_pair  # noqa: E402

CROP = (1024, 768)  #: the region of the photo enlarged 2x into the high image of a "low" pair


def pairs(photo: Path, ratios, rng, folder: Path):
    """(kind, low path, high path, truth high px -> low px) of one large JPEG."""
    full = cv2.imread(str(photo), cv2.IMREAD_COLOR)
    h, w = full.shape[:2]
    for r in ratios:
        low = cv2.resize(full, (int(round(w / r)), int(round(h / r))), interpolation=cv2.INTER_AREA)
        path = folder / f"{photo.stem}_low_x{r:g}.png"
        cv2.imwrite(str(path), low)
        # low px -> photo px is resize_map(w / low width) (per axis); the truth is its inverse
        to_photo = resize_map(w / low.shape[1], h / low.shape[0])
        yield f"high x{r:g}", path, photo, invert(to_photo)
    x0 = int(rng.integers(0, w - CROP[0]))
    y0 = int(rng.integers(0, h - CROP[1]))
    high = cv2.resize(full[y0:y0 + CROP[1], x0:x0 + CROP[0]], (2 * CROP[0], 2 * CROP[1]),
                      interpolation=cv2.INTER_CUBIC)
    path = folder / f"{photo.stem}_high_x2.png"
    cv2.imwrite(str(path), high)
    shift = np.array([[1.0, 0, x0], [0, 1.0, y0], [0, 0, 1.0]])
    yield "low x2", photo, path, (shift @ as_matrix3(invert(resize_map(2.0))))[:2]


def run(low_path: Path, high_path: Path, reduced: bool, config: Config):
    t0 = time.perf_counter()
    if reduced:
        lo, hi = read_pair(low_path, high_path, config)
        result = match(to_grey(lo.image), to_grey(hi.image), config,
                       decoded_factors=(lo.factor, hi.factor))
        factors = (lo.factor, hi.factor)
    else:
        result = match(to_grey(read_image(low_path)), to_grey(read_image(high_path)), config)
        factors = (1, 1)
    return time.perf_counter() - t0, result, factors


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ratios", default="2,3,6")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    ratios = [float(r) for r in args.ratios.split(",")]
    config = Config()
    photos = [p for p in list_photos(find_shared())
              if reduction(read_bytes(p)[1], decode_sides(config)[0]) > 1]
    rng = np.random.default_rng(args.seed)
    print(f"{len(photos)} JPEGs of ../shared decoded at a reduced size (working size "
          f"{config.low_max_side} px); seed {args.seed}\n")
    print("| photo | pair | factors | s full | s reduced | error full px | error reduced px "
          "| gap px |")
    print("|---|---|---|---:|---:|---:|---:|---:|")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, photo in enumerate(photos):
            for kind, low_path, high_path, truth in pairs(photo, ratios, rng, Path(tmp)):
                low_shape = cv2.imread(str(low_path), cv2.IMREAD_GRAYSCALE).shape
                high_shape = cv2.imread(str(high_path), cv2.IMREAD_GRAYSCALE).shape
                first = (k % 2 == 0)  # alternate which reading goes first
                out = {}
                for reduced in ((False, True) if first else (True, False)):
                    out[reduced] = run(low_path, high_path, reduced, config)
                errs, ts = {}, {}
                for reduced, (s, res, _) in out.items():
                    ts[reduced] = s
                    errs[reduced] = (reprojection_error(res.transform, truth, high_shape,
                                                        low_shape)
                                     if res.matched and res.order == "given" else np.inf)
                a, b = out[False][1], out[True][1]
                gap = (mean_transfer_gap(a.transform, b.transform, high_shape)
                       if a.matched and b.matched else np.inf)
                rows.append((ts[False], ts[True], errs[False], errs[True], gap))
                print(f"| {photo.stem} | {kind} | {out[True][2][0]}, {out[True][2][1]} "
                      f"| {ts[False]:.2f} | {ts[True]:.2f} | {errs[False]:.3f} "
                      f"| {errs[True]:.3f} | {gap:.3f} |", flush=True)
    r = np.array(rows)
    print(f"\n{len(rows)} pairs: median s full {np.median(r[:, 0]):.2f}, reduced "
          f"{np.median(r[:, 1]):.2f} (per pair reduced / full: median "
          f"{np.median(r[:, 1] / r[:, 0]):.2f}); matched within 5 px: full "
          f"{int(np.sum(r[:, 2] <= 5))}, reduced {int(np.sum(r[:, 3] <= 5))}; median error full "
          f"{np.median(r[:, 2]):.3f} px, reduced {np.median(r[:, 3]):.3f} px; gap median "
          f"{np.median(r[:, 4]):.3f} px, max {np.max(r[:, 4]):.3f} px")


if __name__ == "__main__":
    main()
