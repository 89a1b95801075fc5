"""Where the finer image's points fall on the occluded pairs: inside the occluder or on the scene.

Usage: python scripts/occluder_points.py [--seed 1] [--photo-step 2] [--ratios 6,8]

The occluded pairs of ``lab real-pairs --sets occluded`` (``realistic.occluded`` on the zoom
pairs of every ``--photo-step``-th photo, ``--seed``), at the ``--ratios`` given. For each, the
finer image is detected at the configured scale nearest the ratio; the occluder is the pixels
that differ from the clean pair. Prints the occluder's share of the area, the points found (and
on the clean finer image), and the share of all points and of the probe's 100 strongest that
lie in the occluder: whether an occluder's edges take a budget the scene needs.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from scalematch.lab.datasets import find_shared, list_photos  # noqa: E402
from scalematch.lab.realpairs import REALISTIC_RATIOS, pair_rng  # noqa: E402
from scalematch.lab.synthetic import pairs_from_photos  # noqa: E402
from scalematch.lab import realistic  # noqa: E402
from scalematch.imageio import read_grey  # noqa: E402
from scalematch.stages.detector import detect, HarrisParams  # noqa: E402
from scalematch.config import Config  # noqa: E402

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--seed", type=int, default=1)
ap.add_argument("--photo-step", type=int, default=2)
ap.add_argument("--ratios", default="6,8")
a = ap.parse_args()
ratios = {float(r) for r in a.ratios.split(",")}
shared = find_shared()
if shared is None:
    sys.exit("../shared is absent")
paths = list_photos(shared)[::a.photo_step]
others = {p.name: read_grey(paths[(i + 1) % len(paths)]) for i, p in enumerate(paths)}
zoom = [z for z in pairs_from_photos(paths, REALISTIC_RATIOS, a.seed) if z.ratio in ratios]
scales = Config().scales
rows = []
for z in zoom:
    q = realistic.occluded(z, others[z.source],
                           pair_rng(a.seed, f"{z.source} occluded", z.ratio))
    box = np.abs(q.high - z.high) > 0
    ys, xs = np.nonzero(box)
    if ys.size == 0:
        continue
    s = min(scales, key=lambda v: abs(np.log(v / z.ratio)))
    kp = detect(q.high, (s,), HarrisParams())[0]
    xy = np.round(kp.xy).astype(int)
    xy[:, 0] = np.clip(xy[:, 0], 0, box.shape[1] - 1)
    xy[:, 1] = np.clip(xy[:, 1], 0, box.shape[0] - 1)
    inside = box[xy[:, 1], xy[:, 0]]
    top = inside[:100]  # detect returns the strongest first
    clean = detect(z.high, (s,), HarrisParams())[0]
    rows.append((z.source[:24], z.ratio, s, box.mean(), len(kp), inside.mean() if len(kp) else np.nan,
                 top.mean() if len(top) else np.nan, len(clean)))
print("photo ratio scale occluder_area points in_occluder(all) in_occluder(top100) points_clean")
for r in rows:
    print(f"{r[0]:24s} {r[1]:4g} {r[2]:5.2f} {r[3]:5.2f} {r[4]:5d} {r[5]:5.2f} {r[6]:5.2f} {r[7]:5d}")
a = np.array([r[3:] for r in rows], float)
print("median: area %.2f, points %d (clean %d), in occluder all %.2f, top100 %.2f" % (
    np.median(a[:, 0]), np.median(a[:, 1]), np.median(a[:, 4]), np.nanmedian(a[:, 2]), np.nanmedian(a[:, 3])))
