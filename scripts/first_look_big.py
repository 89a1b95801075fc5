"""The first look on camera-size photos: tilted and oblique pairs cut from the full-size photos,
and the unrelated 12-16 MP pairs of ``fast_no.py``, the default against first-look
configurations.

Usage: python scripts/first_look_big.py [--photos 12] [--sets tilted,oblique] [--tilts 2,2.83,4]
       [--big-pairs 4] [--methods M1,M2,...]

The pairs are cut from the photos at full size, seed 0, so that the coarser image keeps 1000 px
or more on its shorter side at the working size: the size at which the first look
(``ViewParams.first_look_short_px`` = 500) shrinks it by 2 to 3. *tilted*:
``synthetic.make_tilted_pair`` at ratio 2 (a 1280x960 finer crop; the coarser image the warped
photo, at most 6000x4500). *oblique*: ``synthetic.make_oblique_pair`` at the ``OBLIQUE_CASES``
(an 800x600 finer crop seen obliquely, the coarser image the whole photo zoomed out), the pairs
that only views of the coarser image solve. The
methods are ``fast_no.py``'s (a Config preset, with ``+path=value`` settings), run in this
process alternately pair by pair, their order turned each pair. Prints, per method, the tilted
pairs solved (within 3 px) and wrong, the median time, and the median "no" of the unrelated
pairs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

from fast_no import BIG_PAIRS, alternate  # noqa: E402
from scalematch.lab.datasets import find_shared, list_photos, load_photo  # noqa: E402
from scalematch.lab.evaluation import is_success  # noqa: E402
from scalematch.lab.realpairs import Pair, canonical, pair_error  # noqa: E402
from scalematch.lab.synthetic import OBLIQUE_CASES, make_oblique_pair, make_tilted_pair  # noqa: E402,E501

#: the search without the first look, then the default (which looks at 500 px, from K = 2)
METHODS = ("default+views.first_look_short_px=0", "default")
#: the finer crop, px: a telephoto frame of about 1.2 MP
HIGH_SIZE = (1280, 960)
#: the largest coarser image, px: the warped photo whole
LOW_MAX = (6000, 4500)


def tilted_pairs(shared: Path, photos: int, tilts) -> list:
    paths = list_photos(shared)
    step = max(1, len(paths) // photos)
    out = []
    for n, path in enumerate(paths[::step][:photos]):
        photo = load_photo(path)
        for tilt in tilts:
            rng = np.random.default_rng([0, n, int(tilt * 100)])
            p = make_tilted_pair(photo, 2.0, tilt, rng, HIGH_SIZE, LOW_MAX, source=path.name)
            out.append(Pair("tilted-big", f"{path.name} t{tilt:g}", p.low, p.high,
                            np.vstack([p.truth, [0, 0, 1]]), False, "affine"))
    return out


#: the oblique pairs' finer crop, px
OBLIQUE_HIGH = (800, 600)


def oblique_pairs(shared: Path, photos: int) -> list:
    paths = list_photos(shared)
    step = max(1, len(paths) // photos)
    out = []
    for n, path in enumerate(paths[::step][:photos]):
        photo = load_photo(path)
        for ratio, tilt in OBLIQUE_CASES:
            rng = np.random.default_rng([1, n, int(tilt * 100)])
            p = make_oblique_pair(photo, ratio, tilt, rng, OBLIQUE_HIGH, LOW_MAX, source=path.name)
            out.append(Pair("oblique-big", f"{path.name} r{ratio:g} t{tilt:g}", p.low, p.high,
                            np.vstack([p.truth, [0, 0, 1]]), False, "affine"))
    return out


def report(name: str, pairs: list, methods) -> None:
    """Run ``pairs`` by every method alternately; print solved, wrong and the median time."""
    def judge(pair, t, fwd):
        ok = t is not None and is_success(pair_error(pair, canonical(pair, t, fwd)))
        return (ok, t is not None and not ok)

    rows = alternate(pairs, judge, methods)
    print(f"{name} pairs from the full-size photos ({len(pairs)}), coarser "
          f"{int(np.median([min(p.low.shape) for p in pairs]))} px median shorter side\n")
    print("| method | solved | wrong | median s |\n|---|---:|---:|---:|")
    for m in methods:
        rs = rows[m]
        print(f"| {m} | {sum(r[0][0] for r in rs)} | {sum(r[0][1] for r in rs)} | "
              f"{np.median([r[1] for r in rs]):.2f} |")
    lost = [p.name for p, d, f in zip(pairs, rows[methods[0]], rows[methods[-1]])
            if d[0][0] and not f[0][0]]
    print(f"\nsolved by {methods[0]}, not by {methods[-1]}: {lost or 'none'}\n", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photos", type=int, default=12)
    ap.add_argument("--sets", default="tilted,oblique")
    ap.add_argument("--tilts", default="2,2.83,4")
    ap.add_argument("--big-pairs", type=int, default=len(BIG_PAIRS))
    ap.add_argument("--methods", default=",".join(METHODS))
    a = ap.parse_args()
    methods = tuple(m for m in a.methods.split(",") if m)
    shared = find_shared()
    if shared is None:
        sys.exit("../shared is absent")
    sets = [s for s in a.sets.split(",") if s]
    for name in sets:
        pairs = (tilted_pairs(shared, a.photos, [float(t) for t in a.tilts.split(",")])
                 if name == "tilted" else oblique_pairs(shared, a.photos))
        report(name, pairs, methods)
    if a.big_pairs == 0:
        return
    nulls = [Pair("unrelated-big", f"{x} / {y}", load_photo(shared / "data" / "photos" / x),
                  load_photo(shared / "data" / "photos" / y), None, False, "similarity")
             for x, y in BIG_PAIRS[:a.big_pairs]]
    rows = alternate(nulls, lambda item, t, fwd: (False, t is not None), methods)
    print(f"\nUnrelated 12-16 MP pairs ({len(nulls)}), in process\n")
    print("| method | claims | median s | max s |\n|---|---:|---:|---:|")
    for m in methods:
        secs = [r[1] for r in rows[m]]
        print(f"| {m} | {sum(r[0][1] for r in rows[m])} | {np.median(secs):.2f} | "
              f"{max(secs):.2f} |")


if __name__ == "__main__":
    main()
