"""The point budget (``HarrisParams.min_points``) on occluded and partial pairs at ratios 6 and 8.

Usage: python scripts/point_budget.py [--budgets 0,40,80] [--seed 1] [--photo-step 2] [--ratios 6,8]

The occluded and partial pairs of ``lab real-pairs`` (both orders; ``realistic_sets`` on every
``--photo-step``-th photo, ``--seed``) at the ``--ratios`` given, matched with the default
configuration at each budget in turn, pair by pair (so every budget sees the same load). Prints
each run's outcome and inliers per budget, then the solved and wrong claims and the seconds of
each budget.
"""

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from scalematch import Config, match  # noqa: E402
from scalematch.lab.datasets import find_shared, list_photos  # noqa: E402
from scalematch.lab.evaluation import is_success  # noqa: E402
from scalematch.lab.realpairs import canonical, pair_error, realistic_sets  # noqa: E402

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--budgets", default="0,40,80")
ap.add_argument("--seed", type=int, default=1)
ap.add_argument("--photo-step", type=int, default=2)
ap.add_argument("--ratios", default="6,8")
a = ap.parse_args()
ratios = {float(r) for r in a.ratios.split(",")}
shared = find_shared()
if shared is None:
    sys.exit("../shared is absent")
configs = {b: replace(Config(), harris=replace(Config().harris, min_points=b))
           for b in (int(x) for x in a.budgets.split(","))}
sets = realistic_sets(list_photos(shared)[::a.photo_step], a.seed,
                      ["occluded", "occluded-swapped", "partial", "partial-swapped"])
tally = {b: [0, 0, 0.0] for b in configs}
for name, pairs in sets.items():
    for pair in (p for p in pairs if p.ratio in ratios):
        line = []
        for b, config in configs.items():
            t0 = time.perf_counter()
            r = match(pair.low, pair.high, config)
            tally[b][2] += time.perf_counter() - t0
            est = canonical(pair, r.transform if r.matched else None, r.order == "given")
            ok = r.matched and is_success(pair_error(pair, est))
            tally[b][0] += ok
            tally[b][1] += r.matched and not ok
            line.append(f"{b}:{'ok' if ok else 'WRONG' if r.matched else 'no'}"
                        f"({r.evidence.inliers})")
        print(name, pair.name, " ".join(line), flush=True)
for b, (ok, wrong, seconds) in tally.items():
    print(f"min_points={b}: solved {ok}, wrong {wrong}, {seconds:.0f} s")
