"""Does the pooled vote rank a right view pair first? The vote of each pass of views on the gate's
tilted, steep and oblique pairs, and on its null pairs.

Usage: python scripts/vote_ranking.py [--kinds tilted,steep,oblique,null-unrelated,null-same-photo]
       [--every 1] [--out FILE.jsonl]

For each pair of the regression gate's kinds (``scalematch.lab.regress.cases``, given order:
the pooled vote holds both orders), the plain steps run as ``match`` runs them, then every pass
of views is voted (``viewpass.views_of_images``, ``side_cells``) and its view pairs ranked as
the search ranks them (``stages.vote.best_pairs``, without the bound on the NFA). A view pair at
a scale is *right* when the truth, seen through the two views (``to_view``), is a similarity up
to the tilt the descriptor tolerates (singular values within a factor ``RIGHT_TILT``) at that
scale (within a third octave). Prints, per kind, the rank of the first right pair over the
passes (1st, 2nd or 3rd, later, none) and the log10 NFA of the best cell: the right ones' on
true pairs, the best one's on nulls.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scalematch import Config  # noqa: E402
from scalematch import pipeline as P  # noqa: E402
from scalematch.geometry import compose, invert  # noqa: E402
from scalematch.lab.datasets import find_shared  # noqa: E402
from scalematch.lab.regress import cases  # noqa: E402
from scalematch.search.modes import mode_of  # noqa: E402
from scalematch.result import Direction  # noqa: E402
from scalematch.search.plan import coarser_viewed, search_plan  # noqa: E402
from scalematch.search.shared import Memo, Meter  # noqa: E402
from scalematch.stages.views import ViewParams, tilt_view  # noqa: E402
from scalematch.stages.vote import VoteParams, best_pairs, index_scale  # noqa: E402
from scalematch.working import at_working_size  # noqa: E402

#: a view pair is right when the truth through its views has singular values within this
#: factor of each other: the tilt the descriptor tolerates on its own (docs/design/VIEWS.md,
#: "Why views"); pairs whose own tilt is within it are solved by the plain search and left out
RIGHT_TILT = 2.0
#: ... and a ratio within this factor of the pair's scale (a third octave)
RIGHT_SCALE = 2.0 ** (1.0 / 3.0)
#: view pairs ranked per pass
RANKED = 10


def right(truth3, f_view, c_view, s):
    """Whether the truth (finer px -> coarser px, 3x3) seen through the views is a similarity
    of ratio ``s`` up to the tolerances."""
    t = compose(c_view.to_view, compose(truth3[:2], invert(f_view.to_view)))
    sv = np.linalg.svd(np.asarray(t)[:, :2], compute_uv=False)  # coarser px per finer view px
    if sv[1] <= 0:
        return False
    ratio = 1.0 / math.sqrt(sv[0] * sv[1])
    return sv[0] / sv[1] <= RIGHT_TILT and abs(math.log(ratio / s)) <= math.log(RIGHT_SCALE)


def tilt_of(name: str) -> float:
    """The tilt a gate pair's name gives ("... x2 t2.83", "... oblique t4")."""
    word = next((w for w in name.split() if w.startswith("t") and w[1:2].isdigit()), "t1")
    return float(word[1:])


def ranked_passes(low, high, truth, config):
    """[(pass, [(rank, right, log10 NFA)])] of one pair in the given order."""
    work = at_working_size(low, high, config)
    search = P.Search(work, config, mode_of(config), Memo(), Meter(None, 0))
    plan = search_plan(config, work.scales, P.finer_sides(work))
    out = []
    loose = VoteParams(max_log_nfa=1e9)  # every pair ranked, beyond chance or not
    for step in plan:
        if step.view_pass == 0:
            P.run_step(search, step, 0)
            continue
        directions = [d for d, _ in step.directions]
        viewed = coarser_viewed(directions, P.finer_sides(work), config.views.coarser_directions)
        images = P.views_of_images(search, step, viewed)
        sides, cells = [], []
        for d in directions:
            coarser, finer = d.coarser_finer(images[Direction.GIVEN], images[Direction.SWAPPED])
            for side in ("finer", "coarser"):
                if side == "coarser" and d not in viewed:
                    continue
                sides.append(d)
                cells.append(P.side_cells(finer, coarser, side, config.matcher, config.vote))
        search.memo.cells_tried += sum(c.tried for c in cells)
        nfa = [P.cells_nfa(c, search.memo.cells_tried) for c in cells]
        rows = []
        for rank, r in enumerate(best_pairs(cells, nfa, RANKED, loose)):
            d = sides[r.side]
            ok = False
            if truth is not None:
                coarser, finer = d.coarser_finer(images[Direction.GIVEN], images[Direction.SWAPPED])
                lo_img, hi_img = work.coarser_finer(d)
                full = ViewParams(max_short_side_px=0.0)
                fi, ci = finer.views[r.finer_view], coarser.views[r.coarser_view]
                f_view = P.identity_view(hi_img) if r.finer_view == 0 else \
                    tilt_view(hi_img, fi.tilt, fi.longitude_deg, full)
                c_view = P.identity_view(lo_img) if r.coarser_view == 0 else \
                    tilt_view(lo_img, ci.tilt, ci.longitude_deg, full)
                t = truth if d is Direction.GIVEN else np.linalg.inv(truth)
                s = float(index_scale(r.scale_indices[0])) * fi.scale / ci.scale
                ok = right(t, f_view, c_view, s)
            rows.append((rank, ok, r.log10_nfa))
        out.append((step.view_pass, rows))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kinds", default="tilted,steep,oblique,null-unrelated,null-same-photo")
    ap.add_argument("--every", type=int, default=1, help="every n-th pair of each kind")
    ap.add_argument("--out", help="write one JSON line per pair here")
    args = ap.parse_args()
    config = Config()
    out = open(args.out, "w") if args.out else None
    summary = {}
    for kind in args.kinds.split(","):
        given = [c for c in cases(find_shared(), (kind,)) if c.order == "given"
                 and (c.truth is None or tilt_of(c.name) > RIGHT_TILT)][::args.every]
        for case in given:
            passes = ranked_passes(case.low, case.high, case.truth, config)
            first = next((rank for _, rows in passes for rank, ok, _ in rows if ok), None)
            best = min((n for _, rows in passes for _, _, n in rows), default=math.inf)
            right_nfa = min((n for _, rows in passes for _, ok, n in rows if ok), default=math.nan)
            s = summary.setdefault(kind, {"pairs": 0, "first": 0, "top3": 0, "later": 0,
                                          "none": 0, "best": [], "right": []})
            s["pairs"] += 1
            s["first" if first == 0 else "top3" if first in (1, 2) else "none" if first is None
              else "later"] += 1
            s["best"].append(best)
            if not math.isnan(right_nfa):
                s["right"].append(right_nfa)
            if out:
                out.write(json.dumps({"kind": kind, "pair": case.name, "first_right": first,
                                      "best_log10_nfa": best, "passes": passes},
                                     default=float) + "\n")
                out.flush()
    print("| kind | pairs | a right pair first | 2nd or 3rd | later | none | best cell, "
          "log10 NFA (min / median / max) | right pairs' best |")
    print("|---|---:|---:|---:|---:|---:|---|---|")
    for kind, s in summary.items():
        b = sorted(s["best"])
        r = sorted(s["right"])
        spread = f"{b[0]:.1f} / {b[len(b) // 2]:.1f} / {b[-1]:.1f}" if b else "-"
        rights = f"{r[0]:.1f} to {r[-1]:.1f}" if r else "-"
        print(f"| {kind} | {s['pairs']} | {s['first']} | {s['top3']} | {s['later']} | "
              f"{s['none']} | {spread} | {rights} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
