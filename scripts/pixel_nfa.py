"""The pixels' chance of a map beside its geometry's: what one a-contrario decision would see.

Usage: python scripts/pixel_nfa.py [--sets regress,realistic,nulls,real-nulls] [--seeds 1,2]
       [--ratios 3,6,8] [--nulls 500] [--limit N] [--jobs 2] [--out FILE.jsonl]
       [--summary-only] [--only SETS]

Step 1 of the "one decision" issue: measure before the thirteen rules are replaced by one NFA,
(tests) x (chance of the geometry) x (chance of the pixels). Each run matches a pair as the
product does (``scalematch.match``, the default ``Config``; the homography model on the Oxford
pairs and the fundamental matrix on the 3-D pairs, as the lab runs them) and takes the map it
answered (``result.transform``) or, for a "no", the refused candidate (``result.rejected``;
none when nothing reached the tests or the best attempt was a view's). On that map, at working
size with NaN where an image shows no scene (as ``stages.finalchecks.final_checks`` sees it):

* the geometry: its log10 NFA (the evidence's, or the rejected candidate's);
* the pixels, over the whole overlap of the footprint with the coarser image (no inlier
  vouching): the finer image warped by the map at the uniqueness test's size
  (``uniqueness.unique_template`` without ``vouched``), cut into ``PixelParams.window_px``
  windows; ``j`` of ``m`` agree (ZNCC >= ``window_ncc``) at the map; ``q_elsewhere`` is the
  best share at any placement half a footprint away (``agreement_of``), ``q_nearby`` the best
  at the 8 nearby placements (``near_windows``: shifted, turned, rescaled; its own tiling of
  ``m_near`` windows). The pixel tests are the placements tried: those elsewhere plus the
  nearby ones.
* ``q_hat``, the chance a window agrees at a wrong placement: the rule of succession on the
  best wrong placement's count, ``(c + 1) / (n + 2)`` for c of n windows agreeing (the larger
  of the elsewhere and nearby ones). Never 0 (a clean elsewhere gives about 1/m, not -inf)
  and never 1 (a structure that fits everywhere, q = 1, leaves a tail near 1/e at j = m: no
  count carries it). ``max(q, 1/m)`` is recorded beside it (``*_alt``).
* pixel log10 NFA = log10 tests_pix + log10 P[Bin(m, q_hat) >= j]; combined = geometric log10
  NFA + log10 P[...] + log10 tests_pix.

Sets: ``regress``: the regression gate's pairs (``lab.regress.cases``, every kind, both
orders); ``realistic``: ``lab.realpairs.realistic_sets`` (padded, occluded, partial, relit and
their swapped sets) at ``--ratios`` with ``--seeds``; ``nulls``: the first ``--nulls`` pairs of
``lab.nulls.null_specs``' balanced order, both orders; ``real-nulls``: padded-null and
occluded-null of ``realistic_sets`` at ``--null-seed`` (both orders). The error of a map is
the lab's (EVALUATION.md's grid error; the 3-D pairs' epipolar distance as the gate judges
them); right = under 3 px. One JSON row per run, appended to ``--out`` and resumed from it
(rows stay out of git: ``bench-out/`` is ignored); then Markdown tables: the groups (right
claims, wrong claims, right maps refused, wrong maps refused, nulls), the nulls' most
significant figures, and what the bound that keeps every null out would pass. Needs ../shared.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import dataclasses
import itertools
import json
import math
import multiprocessing as mp
import re
import sys
import time
from pathlib import Path
from typing import Any, Dict, Iterator, NamedTuple, Optional, Sequence, Tuple

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scalematch import Config, match  # noqa: E402
from scalematch.geometry import as_matrix3, resize_map  # noqa: E402
from scalematch.greylevels import grey_levels  # noqa: E402
from scalematch.lab import nulls as NL  # noqa: E402
from scalematch.lab import realpairs as RP  # noqa: E402
from scalematch.lab import regress as RG  # noqa: E402
from scalematch.lab.datasets import find_shared, list_photos, scene_of  # noqa: E402
from scalematch.lab.evaluation import SUCCESS_PX  # noqa: E402
from scalematch.lab.realistic import KINDS as REALISTIC_KINDS  # noqa: E402
from scalematch.result import Direction  # noqa: E402
from scalematch.stages.acontrario import log10_binomial_tail as log10_tail  # noqa: E402
from scalematch.stages.acontrario import succession  # noqa: E402
from scalematch.stages.decision import maps_points  # noqa: E402
from scalematch.stages.pixelcheck import PixelParams, near_windows, perturbations  # noqa: E402
# _far: the placements that agreement_of counts as elsewhere (half a footprint away)
from scalematch.stages.uniqueness import _far, agreement_of, unique_template  # noqa: E402
from scalematch.working import at_working_size  # noqa: E402

SETS = ("regress", "realistic", "nulls", "real-nulls")
#: the figures compared (row keys) and their names in the tables
FIGURES = (("geo_log10_nfa", "geometric"), ("pix_log10_nfa", "pixel"), ("combined", "combined"))
#: the same with the floor max(q, 1/m) instead of the rule of succession
FIGURES_ALT = (("pix_log10_nfa_alt", "pixel, q_hat = max(q, 1/m)"),
               ("combined_alt", "combined, q_hat = max(q, 1/m)"))
#: fewer windows than this is "tiny": 16 windows of 8 px cover a quarter of the 64 px template
TINY_M = 16


# --------------------------------------------------------------------------------------------
# The pixel figures of one map
# --------------------------------------------------------------------------------------------

def pixel_figures(coarser: np.ndarray, finer: np.ndarray, t: np.ndarray,
                  pixel: PixelParams = PixelParams()) -> Dict[str, Any]:
    """The windows of map ``t`` (finer px -> coarser px, working size) over the whole overlap:
    m, j, the shares elsewhere and nearby, the placements tried, q_hat and the tail."""
    out: Dict[str, Any] = {}
    tpl = unique_template(coarser, finer, t, pixel)  # no vouched: the whole overlap
    w = near_windows(coarser, finer, t, pixel)
    out.update(m_near=int(w.windows), near_claim=_plain(w.claimed), q_nearby=_plain(w.nearby))
    if tpl is None:
        out["pix_status"] = "no template (overlap under 256 px at 64 px, flat, or no room)"
        return out
    a = agreement_of(tpl, pixel)
    m = int(a.windows)
    shape = (tpl.low.shape[0] - tpl.tpl.shape[0] + 1, tpl.low.shape[1] - tpl.tpl.shape[1] + 1)
    elsewhere_n = int(_far(shape, tpl, pixel.unique_exclusion).sum())
    nearby_n = len(perturbations(t, finer.shape, pixel))
    out.update(m=m, template_px=[int(s) for s in tpl.tpl.shape], overlap_px=int(tpl.mask.sum()),
               elsewhere_placements=elsewhere_n, nearby_placements=nearby_n)
    if m == 0:
        out["pix_status"] = "no window (every window flat or cut by the mask)"
        return out
    j = int(round(a.claimed * m))
    c_else = int(round(a.elsewhere * m)) if math.isfinite(a.elsewhere) else None
    c_near = int(round(w.nearby * w.windows)) if w.windows and math.isfinite(w.nearby) else None
    shares = [v for v in (a.elsewhere, w.nearby) if math.isfinite(v)]
    if not shares:
        out.update(pix_status="no wrong placement measured", j=j, share_claim=a.claimed)
        return out
    q = max(shares)
    q_hat = _q_hat(c_else, m, c_near, w.windows)
    q_alt = max(q, 1.0 / m)
    tests = elsewhere_n + nearby_n
    tail, tail_alt = log10_tail(m, j, q_hat), log10_tail(m, j, q_alt)
    out.update(disagreeing_blocks(tpl, pixel))
    out.update(pix_status="ok", j=j, share_claim=a.claimed, q_elsewhere=_plain(a.elsewhere),
               count_elsewhere=c_else, count_nearby=c_near, q=q, q_hat=q_hat, q_alt=q_alt,
               log10_tests_pix=math.log10(max(tests, 1)), log10_tail=tail,
               log10_tail_alt=tail_alt)
    return out


def claim_windows(placed, pixel: PixelParams, min_std: float = 1.0) -> Dict[Tuple[int, int], bool]:
    """{(row, col) of the template's window grid: whether it agrees} at the claimed placement:
    the windows ``agreement_map`` counts (wholly in the mask, not flat), each agreeing when its
    ZNCC reaches ``window_ncc`` at the placement within 1 px of the claim where most agree (as
    ``uniqueness._at_claim`` takes the best share there)."""
    import cv2

    side, least = pixel.window_px, pixel.window_ncc
    tpl, mask, low = placed.tpl, placed.mask, placed.low
    h, w = tpl.shape
    shifts = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)
              if 0 <= placed.y0 + dy <= low.shape[0] - h and 0 <= placed.x0 + dx <= low.shape[1] - w]
    agree: Dict[Tuple[int, int], list] = {}
    for oy in range(0, h - side + 1, side):
        for ox in range(0, w - side + 1, side):
            patch = np.ascontiguousarray(tpl[oy:oy + side, ox:ox + side])
            if not mask[oy:oy + side, ox:ox + side].all() or float(patch.std()) <= min_std:
                continue
            y, x = placed.y0 + oy, placed.x0 + ox
            region = np.ascontiguousarray(low[max(y - 1, 0):y + side + 1, max(x - 1, 0):x + side + 1])
            r = cv2.matchTemplate(region, patch, cv2.TM_CCOEFF_NORMED)
            agree[(oy // side, ox // side)] = [
                bool(r[dy + (1 if y >= 1 else 0), dx + (1 if x >= 1 else 0)] >= least)
                if 0 <= dy + (1 if y >= 1 else 0) < r.shape[0]
                and 0 <= dx + (1 if x >= 1 else 0) < r.shape[1] else False
                for dy, dx in shifts]
    if not agree:
        return {}
    best = max(range(len(shifts)), key=lambda k: sum(v[k] for v in agree.values()))
    return {cell: v[best] for cell, v in agree.items()}


def blocks(cells) -> list:
    """Sizes of the 4-connected groups of grid ``cells`` ((row, col)), largest first."""
    left, sizes = set(cells), []
    while left:
        stack, size = [left.pop()], 0
        while stack:
            r, c = stack.pop()
            size += 1
            for n in ((r + 1, c), (r - 1, c), (r, c + 1), (r, c - 1)):
                if n in left:
                    left.remove(n)
                    stack.append(n)
        sizes.append(size)
    return sorted(sizes, reverse=True)


def disagreeing_blocks(placed, pixel: PixelParams) -> Dict[str, Any]:
    """Where the windows that disagree at the claim lie: their 4-connected blocks on the
    window grid (an occluder or a missing part is one block; a copy's misfit is scattered)."""
    grid = claim_windows(placed, pixel)
    off = [cell for cell, ok in grid.items() if not ok]
    sizes = blocks(off)
    return {"grid_windows": len(grid), "grid_agreeing": len(grid) - len(off),
            "disagree_blocks": sizes[:8],
            "largest_block_of_disagreeing": (sizes[0] / len(off)) if off else None}


def _q_hat(c_else: Optional[int], m: int, c_near: Optional[int], m_near: int) -> float:
    """q_hat: the larger rule-of-succession estimate of the two sets of wrong placements."""
    est = []
    if c_else is not None:
        est.append(succession(c_else, m))
    if c_near is not None and m_near:
        est.append(succession(c_near, m_near))
    return max(est)


def working_map(t: np.ndarray, f_coarser: float, f_finer: float) -> np.ndarray:
    """A map between the images given (finer px -> coarser px) between their working copies."""
    t3 = as_matrix3(np.asarray(t, np.float64))
    if f_coarser == 1.0 and f_finer == 1.0:
        return t3
    return as_matrix3(resize_map(1.0 / f_coarser)) @ t3 @ as_matrix3(resize_map(f_finer))


# --------------------------------------------------------------------------------------------
# One run (in a worker process)
# --------------------------------------------------------------------------------------------

def _init_worker() -> None:
    import cv2

    cv2.setNumThreads(1)


def run_one(job: Tuple[str, np.ndarray, np.ndarray, str]) -> Dict[str, Any]:
    """Match one pair as the product does, then the figures of its map (a claim or the
    refused candidate)."""
    run_id, low, high, model = job
    config = Config() if model == Config().model else dataclasses.replace(Config(), model=model)
    t0 = time.perf_counter()
    try:
        r = match(low, high, config)
    except Exception as exc:  # noqa: BLE001 - a crash is recorded, not measured
        return {"id": run_id, "claimed": False, "reason": f"error: {type(exc).__name__}: {exc}",
                "map": None, "seconds": time.perf_counter() - t0}
    row: Dict[str, Any] = {"id": run_id, "claimed": bool(r.matched),
                           "seconds": round(time.perf_counter() - t0, 3),
                           "reason": r.reason or "", "judged_by": r.evidence.judged_by}
    e = r.evidence  # the final check's own figures: windows near the inliers (when consulted)
    row.update(unique_ratio=_plain(e.unique_ratio), near_inlier_windows=int(e.unique_windows),
               near_inlier_claim=_plain(e.windows_agreeing),
               near_inlier_elsewhere=_plain(e.windows_elsewhere))
    if r.matched:
        t, order, lnfa, kept, test = (r.transform, r.order, r.evidence.log10_nfa, r.n_inliers,
                                      "")
        found_model = r.model
    elif r.rejected is not None:
        rej = r.rejected
        t, order, lnfa, kept, test, found_model = (rej.transform, rej.order, rej.log10_nfa,
                                                   rej.n_inliers, rej.test, rej.model)
    else:
        row.update(map=None, test="")
        return row
    order = Direction(order)
    row.update(map="claim" if r.matched else "rejected", test=test, map_model=found_model,
               map_order=order.value, inliers=int(kept), geo_log10_nfa=_plain(float(lnfa)),
               transform=np.round(as_matrix3(np.asarray(t, float)), 9).tolist())
    if not maps_points(found_model):
        row["pix_status"] = "fundamental matrix: no placement"
        return row
    t1 = time.perf_counter()
    work = at_working_size(grey_levels(low, "low"), grey_levels(high, "high"), config)
    coarser, finer = work.shown(order)
    f_coarser, f_finer = (work.f_low, work.f_high) if order is Direction.GIVEN else \
        (work.f_high, work.f_low)
    figs = pixel_figures(coarser, finer, working_map(t, f_coarser, f_finer), config.pixel)
    row.update(figs, working_factors=[work.f_low, work.f_high],
               measure_seconds=round(time.perf_counter() - t1, 3))
    return row


def _plain(v: float) -> Any:
    """A float for JSON: nan and infinities as strings ("nan", "inf", "-inf")."""
    v = float(v)
    return v if math.isfinite(v) else str(v)


def _num(v: Any) -> float:
    """A row's number back (None and "nan" as nan)."""
    return math.nan if v is None else float(v)


# --------------------------------------------------------------------------------------------
# The runs of each set (in the parent): id, what to record, how to judge a map
# --------------------------------------------------------------------------------------------

class Run(NamedTuple):
    id: str
    meta: Dict[str, Any]  #: set, kind, pair, order, ratio, null
    low: np.ndarray
    high: np.ndarray
    model: str
    judge: Any  #: a regress Case, a realpairs Pair, or None (a null: every map is wrong)


def ratio_of(name: str) -> float:
    """The ratio a gate pair's name gives; nan when none (the 3-D pairs, Oxford).

    >>> ratio_of("a.jpg x6 t2.83"), ratio_of("boat 1->3 /4"), ratio_of("unrelated:a>b:x12")
    (6.0, 4.0, 12.0)
    """
    m = re.search(r"(?:^|[ :])[x/](\d+(?:\.\d+)?)(?: |$)", name)
    return float(m.group(1)) if m else math.nan


def regress_runs(shared: Path) -> Iterator[Run]:
    for c in RG.cases(shared):
        null = c.kind in RG.NULL_KINDS
        yield Run(f"regress|{c.id}", {"set": "regress", "kind": c.kind, "pair": c.name,
                                      "order": c.order, "ratio": ratio_of(c.name),
                                      "null": null}, c.low, c.high, c.model,
                  None if null else c)


def realistic_runs(paths: Sequence[Path], seeds: Sequence[int],
                   ratios: Sequence[float]) -> Iterator[Run]:
    wanted = [n for k in REALISTIC_KINDS for n in (k, f"{k}-swapped")]
    for seed in seeds:  # the zoom pairs made once a seed, every kind from them (3-4 GB)
        made = RP.realistic_sets(paths, seed, wanted)
        kept = [p for name in wanted for p in made[name]
                if any(abs(p.ratio - r) < 1e-9 for r in ratios)]
        del made
        for p in kept:
            kind, order = p.set.replace("-swapped", ""), "swapped" if p.swapped else "given"
            yield Run(f"realistic|s{seed}|{kind}|{p.name}|{order}",
                      {"set": "realistic", "kind": kind, "pair": p.name, "order": order,
                       "ratio": p.ratio, "seed": seed, "null": False},
                      p.low, p.high, "similarity", p)


def real_null_runs(paths: Sequence[Path], seed: int) -> Iterator[Run]:
    made = RP.realistic_sets(paths, seed, ["padded-null", "occluded-null"])
    for name, pairs in made.items():
        for p in pairs:
            order = "swapped" if p.swapped else "given"
            yield Run(f"real-nulls|s{seed}|{name}|{p.name}|{order}",
                      {"set": "real-nulls", "kind": name, "pair": p.name, "order": order,
                       "ratio": p.ratio, "seed": seed, "null": True}, p.low, p.high,
                      "similarity", None)


def null_runs(paths: Sequence[Path], count: int) -> Iterator[Run]:
    names = [p.name for p in paths]
    by_name = {p.name: p for p in paths}
    photos: Dict[str, np.ndarray] = {}

    def load(name: str) -> np.ndarray:
        from scalematch.imageio import read_grey

        if name not in photos:
            if len(photos) >= NL.PHOTO_CACHE:
                photos.pop(next(iter(photos)))
            photos[name] = read_grey(by_name[name])
        return photos[name]

    for spec in NL.null_specs(names, seed=0)[:count]:
        pair = NL.make_pair(spec, load)
        low, high = pair.low.astype(np.float32), pair.high.astype(np.float32)
        for order in NL.ORDERS:
            a, b = (low, high) if order == "given" else (high, low)
            yield Run(f"nulls|{spec.pair_id}|{order}",
                      {"set": "nulls", "kind": spec.kind, "pair": spec.pair_id, "order": order,
                       "ratio": spec.ratio, "null": True}, a, b, "similarity", None)


def map_error(run: Run, row: Dict[str, Any]) -> float:
    """The map's error against the truth, as the lab judges it (nan: no truth, or no map)."""
    if run.judge is None or row.get("map") is None:
        return math.nan
    t = np.asarray(row["transform"], float)
    if isinstance(run.judge, RG.Case):
        answer = {"matched": True, "transform": t, "order": row["map_order"],
                  "model": row["map_model"], "seconds": 0.0}
        return _num(RG.judge(run.judge, answer)["error_px"])
    p = run.judge
    return float(RP.pair_error(p, RP.canonical(p, t, row["map_order"] == "given")))


def finished(row: Dict[str, Any], run: Run) -> Dict[str, Any]:
    """The worker's row with the run's record, the map's error and the combined figures."""
    row = {**run.meta, **row}
    err = map_error(run, row)
    row["error_px"] = _plain(err)
    row["right"] = bool(math.isfinite(err) and err < SUCCESS_PX)
    if row.get("pix_status") == "ok":
        geo = _num(row["geo_log10_nfa"])
        tests = row["log10_tests_pix"]
        row["pix_log10_nfa"] = tests + row["log10_tail"]
        row["combined"] = _plain(geo + row["log10_tail"] + tests)
        row["pix_log10_nfa_alt"] = tests + row["log10_tail_alt"]
        row["combined_alt"] = _plain(geo + row["log10_tail_alt"] + tests)
    return row


def runs_of(sets: Sequence[str], shared: Path, args) -> Iterator[Run]:
    paths = list_photos(shared)
    for s in sets:
        if s == "regress":
            runs = regress_runs(shared)
        elif s == "realistic":
            runs = realistic_runs(paths, args.seeds, args.ratios)
        elif s == "nulls":
            runs = null_runs(paths, args.nulls)
        else:
            runs = real_null_runs(paths, args.null_seed)
        yield from itertools.islice(runs, args.limit)


def execute(runs: Iterator[Run], out: Path, jobs: int, done: set) -> None:
    """Each run not ``done`` on ``jobs`` processes, at most two per process in flight (the
    pairs are made as they are needed); rows appended to ``out`` as they come."""
    ctx = mp.get_context("spawn")  # not fork: a forked OpenCV thread pool can hang
    pending: Dict[cf.Future, Run] = {}
    n, t0 = 0, time.perf_counter()
    with cf.ProcessPoolExecutor(jobs, mp_context=ctx, initializer=_init_worker) as pool, \
            out.open("a") as fh:

        def drain(until: int) -> None:
            nonlocal n
            while len(pending) > until:
                ready, _ = cf.wait(pending, return_when=cf.FIRST_COMPLETED)
                for f in ready:
                    run = pending.pop(f)
                    fh.write(json.dumps(finished(f.result(), run)) + "\n")
                    fh.flush()
                    n += 1
                    if n % 20 == 0:
                        print(f"  {n} runs, {time.perf_counter() - t0:.0f} s", file=sys.stderr,
                              flush=True)

        for run in runs:
            if run.id in done:
                continue
            pending[pool.submit(run_one, (run.id, run.low, run.high, run.model))] = run
            drain(2 * jobs)
        drain(0)


# --------------------------------------------------------------------------------------------
# The summary
# --------------------------------------------------------------------------------------------

def group_of(r: Dict[str, Any]) -> str:
    if r["null"]:
        return "null, no map" if r.get("map") is None else (
            "null claimed" if r["claimed"] else "null refused")
    if r.get("map") is None:
        return "no map"
    if not math.isfinite(_num(r.get("error_px"))):
        return "claimed, not judged" if r["claimed"] else "refused, not judged"
    return ("right" if r["right"] else "wrong") + (" claim" if r["claimed"] else " refused")


GROUPS = ("right claim", "wrong claim", "right refused", "wrong refused", "no map",
          "claimed, not judged", "refused, not judged", "null claimed", "null refused",
          "null, no map")


def _f(v: float, spec: str = ".1f") -> str:
    return "-" if not math.isfinite(v) else format(v, spec)


def _spread(values: Sequence[float]) -> str:
    """median [min, max] of the finite values."""
    v = [x for x in values if math.isfinite(x)]
    if not v:
        return "-"
    return f"{np.median(v):.1f} [{min(v):.1f}, {max(v):.1f}]"


def groups_table(rows: Sequence[Dict[str, Any]]) -> str:
    out = ["| set | group | runs | pixel measured | geometric log10 NFA | pixel log10 NFA | "
           "combined | m (median) | j/m (median) | q_hat (median) |",
           "|---|---|---:|---:|---|---|---|---:|---:|---:|"]
    for s in dict.fromkeys(r["set"] for r in rows):
        rs = [r for r in rows if r["set"] == s]
        for g in GROUPS:
            gs = [r for r in rs if group_of(r) == g]
            if not gs:
                continue
            ok = [r for r in gs if r.get("pix_status") == "ok"]
            med = lambda k: _f(float(np.median([_num(r[k]) for r in ok])), ".3g") if ok else "-"  # noqa: E731
            share = _f(float(np.median([r["j"] / r["m"] for r in ok])), ".2f") if ok else "-"
            out.append(f"| {s} | {g} | {len(gs)} | {len(ok)} | "
                       f"{_spread([_num(r.get('geo_log10_nfa')) for r in gs])} | "
                       f"{_spread([_num(r.get('pix_log10_nfa')) for r in ok])} | "
                       f"{_spread([_num(r.get('combined')) for r in ok])} | {med('m')} | "
                       f"{share} | {med('q_hat')} |")
    return "\n".join(out)


def kinds_table(rows: Sequence[Dict[str, Any]]) -> str:
    present = [g for g in GROUPS if any(group_of(r) == g for r in rows)]
    out = ["| set | kind | runs | " + " | ".join(present) + " |",
           "|---|---|---:|" + "---:|" * len(present)]
    for s in dict.fromkeys(r["set"] for r in rows):
        rs = [r for r in rows if r["set"] == s]
        for k in dict.fromkeys(r["kind"] for r in rs):
            ks = [r for r in rs if r["kind"] == k]
            out.append(f"| {s} | {k} | {len(ks)} | " + " | ".join(
                str(sum(group_of(r) == g for r in ks)) for g in present) + " |")
    return "\n".join(out)


def _short(r: Dict[str, Any]) -> str:
    return (f"{r['set']} {r['kind']} {r['pair']} {r['order']}"
            + (f" s{r['seed']}" if "seed" in r else ""))


def _line(r: Dict[str, Any]) -> str:
    return (f"| {_short(r)} | {'claim' if r['claimed'] else r.get('test') or '-'} | "
            f"{r.get('inliers', '-')} | {_f(_num(r.get('geo_log10_nfa')))} | {r.get('m', '-')} | "
            f"{r.get('j', '-')} | {_f(_num(r.get('q_elsewhere')), '.2f')} | "
            f"{_f(_num(r.get('q_nearby')), '.2f')} | {_f(_num(r.get('log10_tests_pix')), '.2f')} | "
            f"{_f(_num(r.get('pix_log10_nfa')))} | {_f(_num(r.get('combined')))} | "
            f"{_f(_num(r.get('error_px')), '.2f')} |")


LINE_HEAD = ("| run | claim or test | inliers | geometric | m | j | q elsewhere | q nearby | "
             "log10 tests_pix | pixel | combined | error px |\n|---|---|---:|---:|---:|---:|---:|"
             "---:|---:|---:|---:|---:|")


POOLS = (("nulls (every set)", lambda r: r["null"] and r.get("map") is not None),
         ("wrong maps, true pairs", lambda r: group_of(r) in ("wrong claim", "wrong refused")),
         ("right claims", lambda r: group_of(r) == "right claim"),
         ("right maps refused", lambda r: group_of(r) == "right refused"))
PERCENTILES = (0, 5, 25, 50, 75, 95, 100)


def distribution_table(rows: Sequence[Dict[str, Any]]) -> str:
    """Each figure's percentiles in the pooled groups (every set)."""
    out = ["| figure | maps of | measured | " + " | ".join(f"p{p}" for p in PERCENTILES) + " |",
           "|---|---|---:|" + "---:|" * len(PERCENTILES)]
    for key, name in FIGURES:
        for pool, keep in POOLS:
            v = [_num(r.get(key)) for r in rows if keep(r)]
            v = [x for x in v if not math.isnan(x)]  # +inf: fewer inliers than a sample
            if v:
                out.append(f"| {name} | {pool} | {len(v)} | " + " | ".join(  # no mean of inf
                    f"{np.percentile(v, p, method='nearest'):.1f}" for p in PERCENTILES) + " |")
    return "\n".join(out)


def blocks_table(rows: Sequence[Dict[str, Any]]) -> str:
    """Where the windows that disagree at a map lie, per pooled group: the share agreeing at
    the claim, and the largest 4-connected block's share of those that disagree (1: one block,
    as an occluder or a missing part leaves; small: scattered)."""
    out = ["| maps of | with a window off | agreeing share p50 [min, max] | largest block's share "
           "p5 / p50 / p95 | one block |", "|---|---:|---|---|---:|"]
    for pool, keep in POOLS:
        rs = [r for r in rows if keep(r) and r.get("grid_windows")]
        off = [r for r in rs if r.get("largest_block_of_disagreeing") is not None]
        if not rs:
            continue
        agree = [r["grid_agreeing"] / r["grid_windows"] for r in rs]
        big = [r["largest_block_of_disagreeing"] for r in off]
        spread = " / ".join(f"{np.percentile(big, q, method='nearest'):.2f}" for q in (5, 50, 95)) \
            if big else "-"
        out.append(f"| {pool} | {len(off)} of {len(rs)} | {np.median(agree):.2f} "
                   f"[{min(agree):.2f}, {max(agree):.2f}] | {spread} | "
                   f"{sum(b == 1.0 for b in big)} |")
    return "\n".join(out)


def occluder_photo(r: Dict[str, Any], names: Sequence[str]) -> Optional[str]:
    """The photo an occluded pair's occluder is cut from, as the lab chose it (None: no
    occluder): ``realpairs.realistic_sets`` takes the photo after the coarser image's in the
    list, the gate the first photo after the finer image's of another scene than it."""
    if r["kind"] not in ("occluded", "occluded-null", "null-occluded"):
        return None
    if r["set"] == "regress":
        if r["kind"] == "occluded":
            photo = r["pair"].rsplit(" x", 1)[0]
        else:
            photo = r["pair"].split(" / ")[1].rsplit(" x", 1)[0]
        photos = RG.Photos([Path(n) for n in names])  # names only: nothing is read
        return photos.name(RG._other_scene(photos, names.index(photo)))
    low = r["pair"].split(" / ")[0] if " / " in r["pair"] else r["pair"].rsplit(" x", 1)[0]
    return names[(names.index(low) + 1) % len(names)]


def mark_occluders(rows: Sequence[Dict[str, Any]], names: Sequence[str]) -> None:
    """``occluder_from_low_scene``: the occluder is cut from a photo of the coarser image's
    scene (``datasets.scene_of``), so a null pair may hold a true match (the occluder's)."""
    for r in rows:
        occ = occluder_photo(r, names)
        low = r["pair"].split(" / ")[0] if " / " in r["pair"] else r["pair"].rsplit(" x", 1)[0]
        r["occluder_from_low_scene"] = bool(occ is not None and scene_of(occ) == scene_of(low))


def is_null_map(r: Dict[str, Any], clean: bool) -> bool:
    """A null run's map; with ``clean``, not one whose occluder shows the coarser image's
    scene."""
    return bool(r["null"] and r.get("map") is not None
                and not (clean and r.get("occluder_from_low_scene")))


def nulls_table(rows: Sequence[Dict[str, Any]], clean: bool = False) -> str:
    """The most significant null map by each figure."""
    nulls = [r for r in rows if is_null_map(r, clean)]
    out = [LINE_HEAD.replace("| run |", "| lowest | run |").replace("|---|---|", "|---|---|---|",
                                                                       1)]
    for key, name in FIGURES:
        v = [r for r in nulls if math.isfinite(_num(r.get(key)))]
        if v:
            out.append(f"| {name} " + _line(min(v, key=lambda r: _num(r[key]))))
    return "\n".join(out)


def bound_table(rows: Sequence[Dict[str, Any]], clean: bool = False) -> str:
    """Per figure: the bound under every null's (its lowest), and what passes under it."""
    nulls = [r for r in rows if is_null_map(r, clean)]
    wrong = [r for r in rows if not r["null"] and r.get("map") is not None
             and math.isfinite(_num(r.get("error_px"))) and not r["right"]]
    right = [r for r in rows if not r["null"] and r["right"]]
    claimed = [r for r in right if r["claimed"]]
    refused = [r for r in right if not r["claimed"]]
    out = ["| figure | lowest null | right maps under it | right claims failing it | "
           "right refused passing it | wrong maps (true pairs) passing it | right maps with "
           "no figure (counted as failing) |",
           "|---|---:|---:|---:|---:|---:|---:|"]
    for key, name in FIGURES + FIGURES_ALT:
        vn = [_num(r.get(key)) for r in nulls if math.isfinite(_num(r.get(key)))]
        if not vn:
            continue
        b = min(vn)
        under = lambda r: math.isfinite(_num(r.get(key))) and _num(r[key]) < b  # noqa: E731
        out.append(f"| {name} | {b:.1f} | {sum(map(under, right))}/{len(right)} | "
                   f"{sum(not under(r) for r in claimed)}/{len(claimed)} | "
                   f"{sum(map(under, refused))}/{len(refused)} | "
                   f"{sum(map(under, wrong))}/{len(wrong)} | "
                   f"{sum(math.isnan(_num(r.get(key))) for r in right)} |")
    return "\n".join(out)


def failing_table(rows: Sequence[Dict[str, Any]], clean: bool = True) -> str:
    """Per set and kind: the right maps (claimed / refused) over each figure's bound (the
    lowest null's), i.e. those a decision at that bound would refuse."""
    nulls = [r for r in rows if is_null_map(r, clean)]
    bounds = {}
    for key, _ in FIGURES:
        vn = [_num(r.get(key)) for r in nulls if math.isfinite(_num(r.get(key)))]
        bounds[key] = min(vn) if vn else math.nan
    out = ["| set | kind | right claims | right refused | " + " | ".join(
        f"{name} >= {_f(bounds[key])}: claims / refused" for key, name in FIGURES) +
        " | pixel log10 NFA of the right claims, median [max] |",
        "|---|---|---:|---:|" + "---:|" * len(FIGURES) + "---|"]
    for s in dict.fromkeys(r["set"] for r in rows):
        for k in dict.fromkeys(r["kind"] for r in rows if r["set"] == s):
            right = [r for r in rows if r["set"] == s and r["kind"] == k and not r["null"]
                     and r["right"]]
            if not right:
                continue
            cl = [r for r in right if r["claimed"]]
            rf = [r for r in right if not r["claimed"]]
            over = lambda rs, key: sum(not (_num(r.get(key)) < bounds[key]) for r in rs)  # noqa: E731
            pix = [_num(r.get("pix_log10_nfa")) for r in cl]
            pix = [v for v in pix if math.isfinite(v)]
            out.append(f"| {s} | {k} | {len(cl)} | {len(rf)} | " + " | ".join(
                f"{over(cl, key)} / {over(rf, key)}" for key, _ in FIGURES) + " | " +
                (f"{np.median(pix):.1f} [{max(pix):.1f}]" if pix else "-") + " |")
    return "\n".join(out)


def odd_table(rows: Sequence[Dict[str, Any]]) -> str:
    """Maps whose pixel figure cannot be computed, q = 1, or tiny m: per group."""
    out = ["| group | maps | not measured | q = 1 | 0 < m < 16 | m = 0 | no placement elsewhere |",
           "|---|---:|---:|---:|---:|---:|---:|"]
    for g in GROUPS:
        gs = [r for r in rows if group_of(r) == g and r.get("map") is not None]
        if not gs:
            continue
        out.append(f"| {g} | {len(gs)} | {sum(r.get('pix_status') != 'ok' for r in gs)} | "
                   f"{sum(_num(r.get('q')) >= 1.0 for r in gs)} | "
                   f"{sum(0 < (r.get('m') or 0) < TINY_M for r in gs)} | "
                   f"{sum(r.get('m') == 0 for r in gs)} | "
                   f"{sum(r.get('pix_status') == 'ok' and r.get('elsewhere_placements') == 0 for r in gs)} |")
    why: Dict[str, int] = {}
    for r in rows:
        if r.get("map") is not None and r.get("pix_status") != "ok":
            why[r.get("pix_status", "?")] = why.get(r.get("pix_status", "?"), 0) + 1
    out += ["", "| why not measured | maps |", "|---|---:|"]
    out += [f"| {k} | {v} |" for k, v in sorted(why.items(), key=lambda kv: -kv[1])]
    return "\n".join(out)


def summary(rows: Sequence[Dict[str, Any]]) -> str:
    right_refused = sorted((r for r in rows if group_of(r) == "right refused"),
                           key=lambda r: _num(r.get("combined")) if
                           math.isfinite(_num(r.get("combined"))) else math.inf)
    parts = [f"{len(rows)} runs; q_hat = (c + 1) / (n + 2) of the best wrong placement.", "",
             "### Groups", "", groups_table(rows), "", "### Per kind", "", kinds_table(rows), "",
             "### Each figure's distribution", "", distribution_table(rows), "",
             "### Where the windows that disagree lie", "", blocks_table(rows), "",
             "### The most significant null map by each figure", "", nulls_table(rows), "",
             "Without the null runs whose occluder is cut from a photo of the coarser image's "
             f"scene ({sum(r['null'] and r.get('occluder_from_low_scene', False) for r in rows)}"
             " runs):", "", nulls_table(rows, clean=True), "",
             "### The bound that keeps every null out", "", bound_table(rows), "",
             "Without the null runs whose occluder shows the coarser image's scene:", "",
             bound_table(rows, clean=True), "",
             "### Right maps over each bound (nulls whose occluder shows the coarser image's "
             "scene left out), per kind", "", failing_table(rows), "",
             "### Right maps refused", "", LINE_HEAD] + [_line(r) for r in right_refused] + [
             "", "### Maps the pixel figure cannot judge", "", odd_table(rows)]
    return "\n".join(parts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", default=",".join(SETS), help=f"of {', '.join(SETS)}")
    ap.add_argument("--seeds", default="1,2", help="the realistic pairs' seeds")
    ap.add_argument("--ratios", default="3,6,8", help="the realistic pairs' ratios")
    ap.add_argument("--nulls", type=int, default=500, help="first N pairs of lab.nulls' order")
    ap.add_argument("--null-seed", type=int, default=0, help="the realistic nulls' seed")
    ap.add_argument("--limit", type=int, default=None, help="at most N runs of each set")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    ap.add_argument("--out", default="bench-out/pixel-nfa/rows.jsonl")
    ap.add_argument("--summary-only", action="store_true", help="tables of the rows in --out")
    ap.add_argument("--only", default="", help="tables of these sets only (default: all)")
    args = ap.parse_args()
    args.seeds = [int(s) for s in args.seeds.split(",") if s]
    args.ratios = [float(r) for r in args.ratios.split(",") if r]
    sets = [s.strip() for s in args.sets.split(",") if s.strip()]
    for s in sets:
        if s not in SETS:
            sys.exit(f"unknown set {s!r}; one of {', '.join(SETS)}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rows = [json.loads(x) for x in out.read_text().splitlines()] if out.exists() else []
    if not args.summary_only:
        shared = find_shared(None)
        if shared is None:
            sys.exit("../shared is absent: this script needs its photos")
        execute(runs_of(sets, shared, args), out, args.jobs, {r["id"] for r in rows})
        rows = [json.loads(x) for x in out.read_text().splitlines()]
    only = [s for s in args.only.split(",") if s]
    for r in rows:  # rows of an older version of ratio_of
        if r["set"] == "regress" and math.isnan(_num(r.get("ratio"))):
            r["ratio"] = ratio_of(r["pair"])
    shared = find_shared(None)
    if shared is not None:
        mark_occluders(rows, [p.name for p in list_photos(shared)])
    print(summary([r for r in rows if not only or r["set"] in only]))


if __name__ == "__main__":
    main()
