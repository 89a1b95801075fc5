"""Under ``--model fundamental``, the matrix and the plane map of each pair side by side: what
``answer.without_parallax`` weighs where a matched matrix shows no parallax of its own.

Usage: python scripts/matrix_and_plane.py [--sets adelaide,ef] [--kinds photos,B/2,A/2]
       [--scenes NAME,...] [--out FILE.jsonl]

For each run (every pair of the sets, both orders; Adelaide as ``scripts/adelaide_pairs.py``
gives it, ef's 8 pairs as ``scalematch lab ef-pairs``), prints the matrix's inliers and parallax
figures (its own 8-point count, the epipole's count through the plane), the plane map's answer
or the test that refused it, the plane's windows near its own inliers
(``answer.plane_near_its_inliers``, where only the pixels refused it), and the answer with its
error against the marked matches (mean symmetric epipolar distance of an F, transfer error of a
plane map; EVALUATION.md). Rows go to ``--out`` (bench-out/ is not committed). Needs ../shared.
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
sys.path.insert(0, str(ROOT / "scripts"))

import adelaide_pairs  # noqa: E402
from scalematch import Config, pipeline  # noqa: E402
from scalematch.answer import plane_near_its_inliers  # noqa: E402
from scalematch.lab.efpairs import ef_folder, load_pair, pair_names  # noqa: E402
from scalematch.stages.finalchecks import near_windows_agree  # noqa: E402


class Seen:
    """What the pipeline weighed in its last call: the working images, matrix and plane."""

    work = None
    matrix = None
    plane = None


def _watch() -> None:
    """Wrap the pipeline's steps so that each match leaves its working images and, where a
    matched matrix shows no parallax, both results in :class:`Seen`."""
    at_working, weigh = pipeline.at_working_size, pipeline.without_parallax

    def at_working_size(*args, **kwargs):
        Seen.work = at_working(*args, **kwargs)
        return Seen.work

    def without_parallax(result, plane, *args, **kwargs):
        Seen.matrix, Seen.plane = result, plane
        return weigh(result, plane, *args, **kwargs)

    pipeline.at_working_size, pipeline.without_parallax = at_working_size, without_parallax


def error_of(transform, model: str, order, a_first: bool, points: np.ndarray) -> float:
    """The error of an answer against the marked matches, px (inf: none)."""
    if transform is None:
        return math.inf
    return adelaide_pairs.answer_error(transform, model, order, a_first, points)


def run(pair, a_first: bool) -> dict:
    """One run of ``pair`` under ``--model fundamental``, with what was weighed."""
    Seen.matrix = Seen.plane = None
    first, second = (pair.a, pair.b) if a_first else (pair.b, pair.a)
    config = Config(model="fundamental")
    r = pipeline.match(first, second, config)
    row = dict(pair=pair.name, order="A->B" if a_first else "B->A", answer=r.model if r.matched
               else "no", error_px=error_of(r.transform, r.model, r.order, a_first, pair.points)
               if r.matched else math.inf, reason=r.reason[:100])
    f, plane = Seen.matrix, Seen.plane
    if f is None:
        return row
    e = f.evidence
    row.update(f_inliers=f.n_inliers, f_error_px=error_of(f.transform, f.model, f.order,
                                                         a_first, pair.points),
               parallax_nfa=e.parallax_log10_nfa, off_plane=e.parallax_points,
               vouched=e.parallax_vouched_points, epipole_nfa=e.epipole_log10_nfa,
               plane="matched" if plane.matched else
               (plane.rejected.test if plane.rejected is not None else "none"))
    cand = plane if plane.matched else plane.rejected
    if cand is not None:
        row.update(plane_error_px=error_of(cand.transform, cand.model, cand.order, a_first,
                                           pair.points), plane_inliers=cand.n_inliers)
    w = plane_near_its_inliers(plane, Seen.work, config)
    if w is not None:
        row.update(near_windows=w.windows, near_claimed=w.claimed, near_nearby=w.nearby,
                   near_agree=bool(near_windows_agree(w, config.decision)))
    return row


def pairs(shared: Path, sets, kinds, names):
    if "adelaide" in sets:
        for name, a, b, points in adelaide_pairs.scenes(shared):
            if not names or name in names:
                for kind in kinds:
                    yield adelaide_pairs.given(name, a, b, points, kind)
    if "ef" in sets:
        folder = ef_folder(shared)
        for name in pair_names(folder):
            if not names or name in names:
                yield load_pair(folder, name)


def _fmt(v) -> str:
    if isinstance(v, float):
        return "-" if not math.isfinite(v) else f"{v:.1f}"
    return str(v)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared")
    ap.add_argument("--sets", default="adelaide,ef")
    ap.add_argument("--kinds", default="photos,B/2,A/2")
    ap.add_argument("--scenes", default="")
    ap.add_argument("--out", type=Path, default=ROOT / "bench-out" / "matrix_and_plane.jsonl")
    args = ap.parse_args()
    _watch()
    names = [s for s in args.scenes.split(",") if s]
    cols = ("pair", "order", "answer", "error_px", "f_inliers", "f_error_px", "parallax_nfa",
            "off_plane", "vouched", "epipole_nfa", "plane", "plane_inliers", "plane_error_px",
            "near_windows", "near_claimed", "near_nearby", "near_agree")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    print("\t".join(cols))
    with args.out.open("w") as out:
        for pair in pairs(args.shared, args.sets.split(","), args.kinds.split(","), names):
            for a_first in (True, False):
                row = run(pair, a_first)
                out.write(json.dumps(row) + "\n")
                print("\t".join(_fmt(row.get(c, "")) for c in cols), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
