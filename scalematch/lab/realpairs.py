"""The real-pair benchmark: what users bring beyond clean synthetic zooms.

docs/DESIGN.md, "What real pairs need", says what each set measures. Sets, made once per run
and given to every method (docs/EVALUATION-TILT.md):

* ``oxford``: the Oxford sequences boat (zoom + rotation), graf and wall (viewpoint), img1
  against img2..img6 with the published homographies, in both directions;
* ``tilted``: synthetic *tilted* zoom pairs from ``shared/data/photos`` (zoom x rotation x tilt
  along a random direction, exact affine truth, ``synthetic.make_tilted_pair``);
* ``zoom``: plain synthetic zoom pairs (EVALUATION.md), the reference of the sets above;
* ``*-swapped``: every pair of ``zoom`` and ``tilted`` given in the other order (finer first);
* ``unrelated``: the low image of one photo against the high image of another scene;
* ``steep``, ``perspective``, ``oblique`` (only when named; docs/design/VIEWS.md): tilted
  pairs at t = 6 and 8, perspective pairs, and pairs whose *finer* image is the oblique one
  (``synthetic.make_oblique_pair``: directional ratios r and r / t, one of them below 1).

Every transform is judged in one canonical direction, from the pair's finer image to its
coarser image (for oxford: img1 -> imgN), by EVALUATION.md's grid error: a method that answers
in the other direction is inverted first. Methods: scalematch (default configuration), OpenCV
SIFT (ratio test 0.8 + RANSAC 3 px, the homography model on oxford and tilted pairs, a
similarity on zoom pairs) and ASIFT (``cv2.AffineFeature`` around SIFT, same matching) on a
subset small enough to finish, each pair in a child process with a time limit.

A benchmark, not a test: nothing here asserts a time. ``scalematch lab real-pairs --help``.
"""

from __future__ import annotations

import json
import math
import multiprocessing as mp
import os
import platform
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import click
import cv2
import numpy as np

from ..geometry import as_matrix3, invert, similarity_parts
from .baselines import RATIO_TEST, detect_and_describe, estimate, ratio_matches, to_uint8
from .datasets import list_photos, other_scene, require_shared, scene_of, shared_option
from .evaluation import is_success, reprojection_error
from .synthetic import (OBLIQUE_CASES, SPREADS, TILTS, make_oblique_pair,
                        make_perspective_pair, make_tilted_pair, pair_rng, pairs_from_photos,
                        unrelated_from_pairs)

#: Oxford sequences of the set: boat (zoom + rotation), graf and wall (viewpoint)
OXFORD = ("boat", "graf", "wall")
#: zoom ratios of the tilted pairs (directional ratios r and r * t: 2 to 16)
TILTED_RATIOS = (2.0, 4.0)
#: zoom ratios of the plain pairs swapped
ZOOM_RATIOS = (2.0, 4.0, 8.0)
#: every ``PHOTO_STEP``-th photo of ../shared (sorted by name) is cut into pairs
PHOTO_STEP = 3
#: unrelated pairs (false-match test)
UNRELATED = 50
#: ASIFT runs on at most this many pairs of each of ``ASIFT_SETS`` (it took 5 s to 26 minutes
#: a pair on this machine's 2 cores)
ASIFT_PAIRS = 3
#: the sets ASIFT is tried on: where viewpoint is the difficulty
ASIFT_SETS = ("oxford", "tilted", "steep", "oblique")
#: seconds ASIFT may take on one pair before it counts as a failure ("timed out"): one boat
#: pair (850x680 px) took 467 s with one OpenCV thread on an otherwise idle core here
ASIFT_TIMEOUT_S = 600.0
#: ASIFT's subset of the tilted pairs is taken among those of at least this tilt
ASIFT_MIN_TILT = 2.83
METHODS = ("scalematch", "sift", "asift")


@dataclass(frozen=True)
class Pair:
    """A pair as given to the methods, with its truth in the canonical direction."""

    set: str
    name: str
    low: np.ndarray = field(repr=False)  #: the image given first
    high: np.ndarray = field(repr=False)  #: the image given second
    #: finer -> coarser truth (3x3); None for unrelated pairs
    truth: Optional[np.ndarray] = field(repr=False)
    swapped: bool  #: True when ``low`` is the finer image (the truth maps low px -> high px)
    model: str  #: the model the peers fit (scalematch's own choice is its default)
    ratio: float = math.nan
    tilt: float = 1.0


def canonical(pair: Pair, t: Optional[np.ndarray], maps_high_to_low: bool) -> Optional[np.ndarray]:
    """The method's transform turned to the pair's finer -> coarser direction."""
    if t is None:
        return None
    t = as_matrix3(t)
    # the truth maps high -> low when the pair is not swapped, low -> high when it is
    same = maps_high_to_low != pair.swapped
    if same:
        return t
    if not abs(np.linalg.det(t)) > 1e-12:  # a degenerate claim (a peer's collapsed fit)
        return np.full((3, 3), np.nan)
    return invert(t)


def pair_error(pair: Pair, t: Optional[np.ndarray]) -> float:
    if pair.truth is None:
        return math.nan
    src, dst = (pair.low, pair.high) if pair.swapped else (pair.high, pair.low)
    return reprojection_error(t, pair.truth, src.shape, dst.shape)


# --------------------------------------------------------------------------------------------
# Sets
# --------------------------------------------------------------------------------------------

def oxford_pairs(shared: Path) -> List[Pair]:
    out = []
    for seq in OXFORD:
        folder = shared / "data" / "oxford" / seq
        if not (folder / "img1.png").is_file():
            continue
        from ..imageio import read_grey

        img1 = read_grey(folder / "img1.png")
        for n in range(2, 7):
            h = np.loadtxt(folder / f"H1to{n}p").reshape(3, 3)
            imgn = read_grey(folder / f"img{n}.png")
            ratio = similarity_parts(h)[0]
            out.append(Pair("oxford", f"{seq} 1->{n}", imgn, img1, h / h[2, 2], False,
                            "homography", ratio))
            out.append(Pair("oxford", f"{seq} {n}->1", img1, imgn, h / h[2, 2], True,
                            "homography", ratio))
    return out


def _photo_sweep(paths: Sequence[Path], ratios: Sequence[float], values: Sequence[float],
                 seed: int, kind: str, make, key: str, short: str) -> List[Pair]:
    """``make(photo, ratio, value, rng, source=...)`` for each photo, ratio and value, drawn
    from ``pair_rng(seed, "<photo> <key> <value>", ratio)``, as Pairs of set ``kind`` named
    "<photo> x<ratio> <short><value>" (``Pair.tilt`` holds the value)."""
    from ..imageio import read_grey

    out = []
    for path in paths:
        photo = read_grey(path)
        for r in ratios:
            for v in values:
                p = make(photo, r, v, pair_rng(seed, f"{path.name} {key} {v}", r),
                         source=path.name)
                out.append(Pair(kind, f"{path.name} x{r:g} {short}{v:g}", p.low, p.high,
                                as_matrix3(p.truth), False, "homography", r, v))
    return out


def tilted_pairs(paths: Sequence[Path], ratios: Sequence[float], tilts: Sequence[float],
                 seed: int) -> List[Pair]:
    """The tilted zoom pairs of ``paths`` (``synthetic.make_tilted_pair``), each photo at each
    ratio and tilt, drawn from ``pair_rng(seed, "<photo> tilt <t>", ratio)``."""
    return _photo_sweep(paths, ratios, tilts, seed, "tilted", make_tilted_pair, "tilt", "t")


def perspective_pairs(paths: Sequence[Path], ratios: Sequence[float], spreads: Sequence[float],
                      seed: int) -> List[Pair]:
    """The perspective zoom pairs of ``paths`` (``synthetic.make_perspective_pair``: the local
    ratio spans ``[ratio, ratio * spread]`` over the footprint, exact homography truth), each
    photo at each ratio and spread, drawn from ``pair_rng(seed, "<photo> spread <k>", ratio)``;
    ``Pair.tilt`` holds the spread."""
    return _photo_sweep(paths, ratios, spreads, seed, "perspective", make_perspective_pair,
                        "spread", "spread")


def oblique_pairs(paths: Sequence[Path], cases: Sequence[Tuple[float, float]],
                  seed: int) -> List[Pair]:
    """The oblique pairs of ``paths`` (``synthetic.make_oblique_pair``: the finer image seen
    obliquely, exact affine truth), each photo at each (ratio, tilt) of ``cases``, drawn from
    ``pair_rng(seed, "<photo> oblique <t>", ratio)``; ``Pair.tilt`` holds the tilt."""
    from ..imageio import read_grey

    out = []
    for path in paths:
        photo = read_grey(path)
        for r, t in cases:
            p = make_oblique_pair(photo, r, t, pair_rng(seed, f"{path.name} oblique {t}", r),
                                  source=path.name)
            out.append(Pair("oblique", f"{path.name} x{r:g} oblique t{t:g}", p.low, p.high,
                            as_matrix3(p.truth), False, "homography", r, t))
    return out


def swap(pairs: Sequence[Pair], name: str) -> List[Pair]:
    """Every pair given in the other order (finer image first), in the set ``name``."""
    return [Pair(name, p.name, p.high, p.low, p.truth, True, p.model, p.ratio, p.tilt)
            for p in pairs]


#: Tilts of the steep sets (docs/design/VIEWS.md, "The third pass"; ``scripts/steep_views.py``)
STEEP_TILTS = (6.0, 8.0)


def synthetic_sets(paths: Sequence[Path], seed: int, log=lambda s: None,
                   wanted: Optional[Sequence[str]] = None) -> Dict[str, List[Pair]]:
    """The synthetic sets named in ``wanted`` (only those are made; None: those of
    ``SET_ORDER``): zoom pairs, tilted pairs (t 1.41-4), steep ones (t 6 and 8), perspective
    ones (spreads 4 and 8), each also swapped, and unrelated pairs."""
    wanted = SET_ORDER if wanted is None else wanted
    out: Dict[str, List[Pair]] = {}
    if {"zoom", "zoom-swapped"} & set(wanted):
        zoom = [Pair("zoom", f"{p.source} x{p.ratio:g}", p.low, p.high, as_matrix3(p.truth),
                     False, "similarity", p.ratio)
                for p in pairs_from_photos(paths, ZOOM_RATIOS, seed)]
        log(f"made {len(zoom)} zoom pairs")
        out.update({"zoom": zoom, "zoom-swapped": swap(zoom, "zoom-swapped")})
    for name, make in (("tilted", lambda: tilted_pairs(paths, TILTED_RATIOS, TILTS, seed)),
                       ("steep", lambda: [replace(p, set="steep") for p in tilted_pairs(
                           paths, TILTED_RATIOS, STEEP_TILTS, seed)]),
                       ("perspective", lambda: perspective_pairs(paths, TILTED_RATIOS, SPREADS,
                                                                 seed)),
                       ("oblique", lambda: oblique_pairs(paths, OBLIQUE_CASES, seed))):
        if {name, f"{name}-swapped"} & set(wanted):
            pairs = make()
            log(f"made {len(pairs)} {name} pairs")
            out.update({name: pairs, f"{name}-swapped": swap(pairs, f"{name}-swapped")})
    if "unrelated" in wanted:
        zp = list(pairs_from_photos(paths, (2.0, 4.0), seed))
        out["unrelated"] = [Pair("unrelated", f"{u.source} / {u.high_source}", u.low, u.high,
                                 None, False, "similarity", u.ratio)
                            for u in unrelated_from_pairs(zp, UNRELATED,
                                                          np.random.default_rng([seed, 1]),
                                                          scene_of)]
    return out


# --------------------------------------------------------------------------------------------
# Methods: (pair) -> (transform or None, maps_high_to_low, info)
# --------------------------------------------------------------------------------------------

#: Ratios of the realistic sets (EVALUATION.md: "at ratios 2 to 8")
REALISTIC_RATIOS = (2.0, 3.0, 4.0, 6.0, 8.0)
#: Null pairs of each realistic null set (and as many swapped)
REALISTIC_NULLS = 100
#: The Oxford sequences of the realistic set: blur (bikes, trees), light (leuven), JPEG (ubc),
#: zoom + rotation (boat) and viewpoint (graf, wall), img1 against img2..img6 shrunk by these
OXFORD_ZOOM_SEQUENCES = ("bikes", "trees", "leuven", "ubc", "boat", "graf", "wall")
OXFORD_ZOOM_SHRINKS = (2.0, 4.0, 8.0)


def realistic_sets(paths: Sequence[Path], seed: int, wanted: Sequence[str],
                   log=lambda s: None) -> Dict[str, List[Pair]]:
    """The sets of pairs with what real photographs bring (``lab.realistic``), named in
    ``wanted``: zoom pairs at ``REALISTIC_RATIOS`` with one change each (padded, occluded,
    partial, relit; each also swapped) and the null pairs with the same changes (padded-null:
    both images on canvases; occluded-null), ``REALISTIC_NULLS`` of each, also swapped.

    Each change draws from ``pair_rng(seed, "<photo> <kind>", ratio)``; an occluder is cut from
    the next photo of ``paths`` of none of the pair's scenes (``datasets.other_scene``).
    """
    from ..imageio import read_grey
    from . import realistic

    out: Dict[str, List[Pair]] = {}
    kinds = [k for k in realistic.KINDS if {k, f"{k}-swapped"} & set(wanted)]
    nulls = [k for k in ("padded-null", "occluded-null") if k in wanted]
    if not kinds and not nulls:
        return out
    zoom = list(pairs_from_photos(paths, REALISTIC_RATIOS, seed))
    names = [p.name for p in paths]
    read: Dict[int, np.ndarray] = {}

    def occluder(*sources: str) -> np.ndarray:  # a photo of none of the pair's scenes
        k = other_scene(names, names.index(sources[0]), sources)
        if k not in read:
            read[k] = read_grey(paths[k])
        return read[k]

    def change(kind: str, z, rng):
        if kind == "occluded":
            return realistic.occluded(z, occluder(z.source), rng)
        return {"padded": realistic.padded, "partial": realistic.partial,
                "relit": realistic.relit}[kind](z, rng)

    for kind in kinds:
        pairs = []
        for z in zoom:
            q = change(kind, z, pair_rng(seed, f"{z.source} {kind}", z.ratio))
            pairs.append(Pair(kind, f"{z.source} x{z.ratio:g}", q.low, q.high,
                              as_matrix3(q.truth), False, "similarity", z.ratio))
        log(f"made {len(pairs)} {kind} pairs")
        out.update({kind: pairs, f"{kind}-swapped": swap(pairs, f"{kind}-swapped")})
    for name in nulls:
        unrelated = unrelated_from_pairs(zoom, REALISTIC_NULLS,
                                         np.random.default_rng([seed, 2, len(name)]), scene_of)
        pairs = []
        for u in unrelated:
            rng = pair_rng(seed, f"{u.source} / {u.high_source} {name}", u.ratio)
            q = (realistic.padded_null(u, rng) if name == "padded-null"
                 else realistic.occluded(u, occluder(u.source, u.high_source), rng))
            pairs.append(Pair(name, f"{u.source} / {u.high_source} x{u.ratio:g}", q.low,
                              q.high, None, False, "similarity", u.ratio))
        log(f"made {len(pairs)} {name} pairs")
        out[name] = pairs + swap(pairs, name)
    return out


def oxford_zoom_pairs(shared: Path) -> List[Pair]:
    """The Oxford sequences as real degradations with a zoom (EVALUATION.md): high = img1,
    low = imgN shrunk by 2, 4 or 8, truth the shrink composed with H1toN; also swapped."""
    from ..imageio import read_grey
    from .realistic import oxford_zoom

    out = []
    for seq in OXFORD_ZOOM_SEQUENCES:
        folder = shared / "data" / "oxford" / seq
        if not (folder / "img1.png").is_file():
            continue
        img1 = read_grey(folder / "img1.png")
        for n in range(2, 7):
            h1n = np.loadtxt(folder / f"H1to{n}p").reshape(3, 3)
            imgn = read_grey(folder / f"img{n}.png")
            for k in OXFORD_ZOOM_SHRINKS:
                low, high, truth = oxford_zoom(img1, imgn, h1n, k)
                out.append(Pair("oxford-zoom", f"{seq} 1->{n} /{k:g}", low, high, truth, False,
                                "homography", k * similarity_parts(h1n)[0]))
    return out + swap(out, "oxford-zoom")


def run_scalematch(pair: Pair) -> Tuple[Optional[np.ndarray], bool, Dict[str, Any]]:
    from ..pipeline import match

    from ..config import Config

    # the model the peers fit on oxford (EVALUATION.md: boat's truth is a homography); the
    # default configuration elsewhere, as a user would run it
    r = match(pair.low, pair.high, Config(model="homography") if pair.set == "oxford" else Config())
    e = r.evidence
    info = {"inliers": r.n_inliers, "order": r.order, "model": r.model, "reason": r.reason,
            "view_tilt": e.view_tilt, "best_inliers": e.inliers, "log10_nfa": e.log10_nfa,
            "judged_by": e.judged_by, "unique_ratio": e.unique_ratio,
            "second_inliers": e.second_inliers, "parallax": e.parallax,
            "pixel_margin": e.pixel_margin, "footprint_inside": e.footprint_inside,
            "unique_windows": e.unique_windows, "windows_agreeing": e.windows_agreeing,
            "windows_elsewhere": e.windows_elsewhere, "final_margin": e.final_margin,
            "near_windows": e.near_windows, "near_windows_agreeing": e.near_windows_agreeing,
            "near_windows_nearby": e.near_windows_nearby}
    return (r.transform if r.matched else None), r.order == "given", info


def _peer(pair: Pair, detector) -> Tuple[Optional[np.ndarray], bool, Dict[str, Any]]:
    xy_l, d_l = detect_and_describe(detector, to_uint8(pair.low))
    xy_h, d_h = detect_and_describe(detector, to_uint8(pair.high))
    m = ratio_matches(d_h, d_l, cv2.NORM_L2, RATIO_TEST)
    t, n = estimate(xy_h[m[:, 0]], xy_l[m[:, 1]], pair.model)
    return t, True, {"inliers": n, "matches": int(len(m))}


def run_sift(pair: Pair):
    return _peer(pair, cv2.SIFT_create())


def run_asift(pair: Pair):
    return _peer(pair, cv2.AffineFeature_create(cv2.SIFT_create()))


RUNNERS = {"scalematch": run_scalematch, "sift": run_sift, "asift": run_asift}


def _child(name: str, pair: Pair, queue) -> None:
    cv2.setNumThreads(1)
    t0 = time.perf_counter()
    t, fwd, info = RUNNERS[name](pair)
    queue.put((t, fwd, info, time.perf_counter() - t0))


def run_limited(name: str, pair: Pair, timeout: float):
    """Run a method in a child process; (t, maps_high_to_low, info, seconds) or a time-out."""
    ctx = mp.get_context("spawn")  # not fork: a forked OpenCV thread pool can hang
    q = ctx.Queue()
    proc = ctx.Process(target=_child, args=(name, pair, q))
    proc.start()
    try:
        return q.get(timeout=timeout)
    except Exception:  # noqa: BLE001 - queue.Empty: the limit passed
        return None, True, {"reason": f"timed out after {timeout:g} s"}, timeout
    finally:
        proc.kill()
        proc.join()


#: What a row keeps of a method's own figures
JUDGED_KEYS = ("inliers", "order", "model", "reason", "view_tilt", "best_inliers", "log10_nfa",
               "judged_by", "unique_ratio", "second_inliers", "parallax", "pixel_margin",
               "footprint_inside", "unique_windows", "windows_agreeing", "windows_elsewhere",
               "final_margin", "near_windows", "near_windows_agreeing", "near_windows_nearby")


def judge(method: str, pair: Pair, out) -> Dict[str, Any]:
    t, fwd, info, seconds = out
    est = canonical(pair, t, fwd)
    err = pair_error(pair, est)
    return {"set": pair.set, "pair": pair.name, "method": method, "ratio": pair.ratio,
            "tilt": pair.tilt, "claimed": t is not None, "error_px": err,
            "success": bool(pair.truth is not None and is_success(err)),
            "false_claim": bool(pair.truth is None and t is not None), "seconds": seconds,
            **{k: v for k, v in info.items() if k in JUDGED_KEYS}}


def asift_subset(pairs: Sequence[Pair], n: int) -> List[Pair]:
    """``n`` pairs spread evenly over ``pairs`` (the order they were made in), taken among the
    pairs of tilt >= ``ASIFT_MIN_TILT`` when there are any: where ASIFT is meant to help."""
    steep = [p for p in pairs if p.tilt >= ASIFT_MIN_TILT]
    pairs = steep or list(pairs)
    if len(pairs) <= n:
        return list(pairs)
    idx = np.linspace(0, len(pairs) - 1, n).round().astype(int)
    return [pairs[i] for i in idx]


# --------------------------------------------------------------------------------------------
# Summary
# --------------------------------------------------------------------------------------------

def summarise(rows: Sequence[Dict[str, Any]]) -> List[Dict[str, Any]]:
    """Per (set, method): pairs, solved, rate, median error of successes, false claims, time."""
    out = []
    known = SET_ORDER + EXTRA_SETS + REALISTIC_SETS
    keys = sorted({(r["set"], r["method"]) for r in rows},
                  key=lambda k: (known.index(k[0]) if k[0] in known else 99,
                                 METHODS.index(k[1])))
    for s, m in keys:
        rs = [r for r in rows if r["set"] == s and r["method"] == m]
        ok = [r for r in rs if r["success"]]
        out.append({"set": s, "method": m, "pairs": len(rs), "solved": len(ok),
                    "rate": len(ok) / len(rs) if rs else math.nan,
                    "median_error_px": float(np.median([r["error_px"] for r in ok]))
                    if ok else math.nan,
                    "false_claims": sum(r["claimed"] and not r["success"] for r in rs),
                    "median_s": float(np.median([r["seconds"] for r in rs]))})
    return out


SET_ORDER = ("oxford", "zoom", "zoom-swapped", "tilted", "tilted-swapped", "unrelated")
#: Sets run only when named (``--sets``), being slower: tilts 6 and 8, perspective pairs, an
#: oblique finer image (docs/design/VIEWS.md)
EXTRA_SETS = ("steep", "steep-swapped", "perspective", "perspective-swapped", "oblique",
              "oblique-swapped")
#: The realistic sets (``lab.realistic``, EVALUATION.md "Pairs with what real photographs
#: bring"), run only when named; ``scalematch lab real-pairs --sets realistic`` names them all
REALISTIC_SETS = ("padded", "padded-swapped", "occluded", "occluded-swapped", "partial",
                  "partial-swapped", "relit", "relit-swapped", "oxford-zoom", "padded-null",
                  "occluded-null")
#: The sets reported by tilt (or spread), with the values and the column label
BY_TILT = (("tilted", TILTS, "t", "tilt"), ("steep", STEEP_TILTS, "t", "tilt"),
           ("perspective", SPREADS, "spread", "tilt"),
           ("oblique", tuple(t for _, t in OBLIQUE_CASES), "t", "tilt"),
           ("padded", REALISTIC_RATIOS, "ratio", "ratio"),
           ("occluded", REALISTIC_RATIOS, "ratio", "ratio"),
           ("partial", REALISTIC_RATIOS, "ratio", "ratio"),
           ("relit", REALISTIC_RATIOS, "ratio", "ratio"))


def by_tilt(rows: Sequence[Dict[str, Any]]) -> List[Tuple[str, str, float, int, int]]:
    """(set, method, value, solved, pairs) for the sets of ``BY_TILT``: the tilted, steep and
    perspective sets by tilt (or spread), the realistic ones by ratio."""
    out = []
    for family, values, _, key in BY_TILT:
        for s in (family, f"{family}-swapped"):
            for m in METHODS:
                for t in values:
                    rs = [r for r in rows if r["set"] == s and r["method"] == m
                          and r[key] == t]
                    if rs:
                        out.append((s, m, t, sum(r["success"] for r in rs), len(rs)))
    return out


#: Title and protocol line of the two sections this command writes: the real pairs, and the
#: realistic pairs (every set run is one of ``REALISTIC_SETS``)
SECTIONS = {
    "real-pairs": ("Real pairs, either order, tilt",
                   "Protocol: [EVALUATION-TILT.md](../EVALUATION-TILT.md)."),
    "realistic": ("Pairs with what real photographs bring",
                  "Protocol: ../shared/EVALUATION.md, \"Pairs with what real photographs "
                  "bring\" (`scalematch.lab.realistic`): no-data borders (padded), occluders, "
                  "partial overlap, relighting, the Oxford sequences with a zoom, and null pairs "
                  "with the same changes."),
}


def section_of(sets: Sequence[str]) -> str:
    """The section a run's rows go to: "realistic" when every set is one of those."""
    return "realistic" if sets and all(s in REALISTIC_SETS for s in sets) else "real-pairs"


def _nth(step: int) -> str:
    """'2nd', '3rd', '4th' ... ('photo' for every one).

    >>> [_nth(k) for k in (1, 2, 3, 4, 11, 12, 21)]
    ['photo', '2nd', '3rd', '4th', '11th', '12th', '21st']
    """
    if step == 1:
        return "photo"
    suffix = "th" if 10 <= step % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(step % 10, "th")
    return f"{step}{suffix}"


def markdown(summary, tilt_rows, runs: Sequence[Dict[str, Any]],
             section: str = "real-pairs") -> str:
    """The Markdown section: the runs whose rows it reports, the table per set, the tilt table."""
    title, protocol = SECTIONS[section]
    lines = [f"## {title}", "", f"{protocol} Runs reported (the same pairs: same seed and "
             "photos):", ""]
    for m in runs:
        lines.append(f"- `{m.get('command', '?')}`: {m.get('date', '?')}, {m.get('machine', '?')}, "
                     f"load average at start {m.get('load', '?')}, seed {m.get('seed', '?')}, "
                     f"{m.get('photos', '?')} photos "
                     f"(every {_nth(m.get('photo_step', PHOTO_STEP))} of ../shared/data/photos)")
    lines += ["",
             "Success: grid error < 3 px in the coarser image, judged from the finer image to the "
             "coarser one whichever order the method answers in. \"wrong claims\" counts transforms "
             "claimed that are not a success (on unrelated pairs: any claim). ASIFT ran on a "
             "subset (column pairs).", "",
             "| set | method | pairs | solved | rate | median error px | wrong claims | "
             "median s |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in summary:
        err = "-" if math.isnan(r["median_error_px"]) else f"{r['median_error_px']:.2f}"
        null = r["set"] in NULL_SETS
        rate = "-" if null else f"{100 * r['rate']:.0f} %"
        solved = "-" if null else str(r["solved"])
        lines.append(f"| {r['set']} | {r['method']} | {r['pairs']} | {solved} | {rate} | {err} | "
                     f"{r['false_claims']} | {r['median_s']:.2f} |")
    for family, values, label, _ in BY_TILT:
        sets = (family, f"{family}-swapped")
        if not any(ss in sets for ss, *_ in tilt_rows):
            continue
        lines += ["", f"{family.capitalize()} pairs by {'tilt' if label == 't' else label} "
                  "(solved / pairs):", "",
                  "| set | method | " + " | ".join(f"{label} = {t:g}" for t in values) + " |",
                  "|---|---|" + "---:|" * len(values)]
        for s in sets:
            for m in METHODS:
                cells = {t: f"{k}/{n}" for ss, mm, t, k, n in tilt_rows if ss == s and mm == m}
                if cells:
                    lines.append(f"| {s} | {m} | "
                                 + " | ".join(cells.get(t, "-") for t in values) + " |")
    return "\n".join(lines) + "\n"


#: The sets whose pairs show different scenes: any claim there is false
NULL_SETS = ("unrelated", "padded-null", "occluded-null")


def markers(section: str, command: str = "scalematch lab real-pairs") -> Tuple[str, str]:
    """The begin and end markers of a section that ``command`` writes into a document."""
    return (f"<!-- {section}: begin (written by {command}) -->", f"<!-- {section}: end -->")


MARK_BEGIN, MARK_END = markers("real-pairs")


def write_section(doc: Path, text: str, section: str = "real-pairs",
                  command: str = "scalematch lab real-pairs") -> None:
    """Put ``text`` between the markers of ``section`` in ``doc`` (appended when they are
    absent); the rest of ``doc`` is kept as it is."""
    begin, end = markers(section, command)
    old = doc.read_text() if doc.is_file() else ""
    block = f"{begin}\n{text}{end}\n"
    if begin in old and end in old:
        head, rest = old.split(begin, 1)
        tail = rest.split(end, 1)[1].lstrip("\n")
        new = head + block + ("\n" + tail if tail else "")
    else:
        new = (old.rstrip("\n") + "\n\n" if old.strip() else "") + block
    doc.write_text(new)


@click.command("real-pairs", context_settings={"help_option_names": ["-h", "--help"]})
@shared_option
@click.option("--sets", default=",".join(SET_ORDER), show_default=True,
              help="Comma-separated sets to run; also " + ", ".join(EXTRA_SETS)
                   + " (tilts 6 and 8, perspective pairs and oblique finer images: "
                   "docs/design/VIEWS.md)"
                   " and " + ", ".join(REALISTIC_SETS) + " ('realistic': all of these; they "
                   "are written to their own section).")
@click.option("--methods", default=",".join(METHODS), show_default=True)
@click.option("--photo-step", type=click.IntRange(min=1), default=PHOTO_STEP, show_default=True,
              help="Use every N-th photo.")
@click.option("--asift-pairs", type=click.IntRange(min=0), default=ASIFT_PAIRS, show_default=True,
              help="ASIFT pairs per set (it is slow).")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--out-dir", type=click.Path(file_okay=False, path_type=Path),
              default=Path("bench-out/real"), show_default=True)
@click.option("--merge-rows", type=click.Path(dir_okay=False, exists=True, path_type=Path),
              multiple=True, help="rows.json of an earlier run (e.g. ASIFT alone, which is slow "
                                  "and does not change with scalematch) to report with this one; "
                                  "with --methods '' only these are reported (no run).")
@click.option("--write-doc", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write the tables into this Markdown file (its real-pairs section).")
def real_pairs_command(shared, sets, methods, photo_step, asift_pairs, seed, out_dir, merge_rows,
                       write_doc):
    """Real pairs: the Oxford sequences both ways, tilted zoom pairs, every pair swapped, and
    unrelated pairs, for scalematch, SIFT and ASIFT (on a subset) in one run.

    \b
    Example:
      scalematch lab real-pairs --write-doc docs/results/BENCHMARKS.md
      scalematch lab real-pairs --sets oxford --methods scalematch,sift
    """
    import datetime as _dt
    import sys

    shared = require_shared(shared, "data")  # its photos, and its Oxford sequences
    wanted = [s.strip() for s in sets.split(",") if s.strip()]
    wanted = [x for s in wanted for x in (REALISTIC_SETS if s == "realistic" else (s,))]
    known = SET_ORDER + EXTRA_SETS + REALISTIC_SETS
    for s in wanted:
        if s not in known:
            raise click.BadParameter(f"unknown set {s!r}; one of {', '.join(known)}",
                                     param_hint="--sets")
    section = section_of(wanted)
    names = [m.strip() for m in methods.split(",") if m.strip()]
    for m in names:
        if m not in METHODS:
            raise click.BadParameter(f"unknown method {m!r}", param_hint="--methods")
    log = lambda s: click.echo(s, err=True)
    paths = list_photos(shared)[::photo_step]
    pool: Dict[str, List[Pair]] = {}
    if not names:  # report the rows of earlier runs only
        wanted = []
    elif any(s != "oxford" for s in wanted):
        pool.update(synthetic_sets(paths, seed, log, wanted))
        pool.update(realistic_sets(paths, seed, wanted, log))
    if names and "oxford-zoom" in wanted:
        pool["oxford-zoom"] = oxford_zoom_pairs(shared)
    if names and "oxford" in wanted:
        pool["oxford"] = oxford_pairs(shared)
    meta = {"date": _dt.datetime.now().strftime("%Y-%m-%d %H:%M"), "seed": seed,
            "machine": f"{platform.machine()}, {os.cpu_count()} cores",
            "load": " ".join(f"{v:.1f}" for v in os.getloadavg()), "photos": len(paths),
            "photo_step": photo_step}
    rows = []
    out_dir.mkdir(parents=True, exist_ok=True)
    for s in wanted:
        for m in names:
            pairs = pool.get(s, [])
            if m == "asift":
                if s not in ASIFT_SETS:
                    continue
                pairs = asift_subset(pairs, asift_pairs)
            t0 = time.perf_counter()
            for p in pairs:
                out = (run_limited(m, p, ASIFT_TIMEOUT_S) if m == "asift"
                       else _timed(RUNNERS[m], p))
                rows.append(judge(m, p, out))
            done = [r for r in rows if r["set"] == s and r["method"] == m]
            log(f"{s:15s} {m:10s} {sum(r['success'] for r in done)}/{len(done)} solved, "
                f"{sum(r['false_claim'] for r in done)} false, {time.perf_counter() - t0:.0f} s")
            (out_dir / "rows.json").write_text(json.dumps(rows, indent=1, default=str))
    meta["command"] = ("scalematch lab real-pairs " + " ".join(sys.argv[3:])).strip()
    runs = []
    if names:
        (out_dir / "rows.json").write_text(json.dumps(rows, indent=1, default=str))
        (out_dir / "meta.json").write_text(json.dumps(meta))
        runs.append(meta)
    for extra in merge_rows:
        seen = {(q["set"], q["method"]) for q in rows}
        rows = rows + [r for r in json.loads(extra.read_text()) if (r["set"], r["method"]) not in seen]
        info = extra.parent / "meta.json"
        runs.append(json.loads(info.read_text()) if info.is_file() else {"command": str(extra)})
    text = markdown(summarise(rows), by_tilt(rows), runs, section)
    (out_dir / f"{section}.md").write_text(text)
    click.echo(text)
    if write_doc is not None:
        write_section(write_doc, text, section)
        log(f"wrote {write_doc}")


def _timed(fn, pair: Pair):
    t0 = time.perf_counter()
    t, fwd, info = fn(pair)
    return t, fwd, info, time.perf_counter() - t0
