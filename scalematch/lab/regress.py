"""The regression gate: a fixed sample of every kind of pair, in both orders, against a baseline.

A change that helps one kind of pair can cost another that nobody ran (EVALUATION.md, "Every
kind at once"). The gate runs, in one command and within 7 minutes on 2 quiet cores, a fixed
and stratified sample of every kind of pair the lab knows, and compares each answer with the
baseline committed in ``tests/regress/baseline.json``:

* synthetic zoom pairs at ratios 2 to 16 (``zoom``), and zoom pairs whose finer image is
  30-50 % flat or clipped at ratios 8 to 16 (``flat``: ``synthetic.make_flat_pair``);
* the realistic kinds (``padded``, ``occluded``, ``partial``, ``relit``: ``lab.realistic``);
* ``tilted``, ``steep``, ``oblique`` and ``perspective`` pairs (``lab.realpairs``);
* the Oxford sequences with the homography model (``oxford``) and with a zoom (``oxford-zoom``);
* the real 3-D pairs of ``shared/data/ef`` with the fundamental matrix (``ef``);
* null pairs: unrelated photos and same-photo halves (``lab.nulls``), and unrelated pairs on
  black-cornered canvases or with an occluder (``null-padded``, ``null-occluded``).

Every pair runs in both orders. A run is *solved* when its answer is within
``evaluation.SUCCESS_PX`` of the truth (EVALUATION.md's grid error; for ``ef`` the mean
symmetric epipolar distance of the clicked points, ``efpairs.SOLVED_PX``), and a *wrong claim*
when it claims an answer that is not solved (on a null pair: any claim). Against the baseline,
a run solved there and not here is *lost*; a wrong claim not in the baseline is *new*. The gate
fails (exit 1) on any lost run or new wrong claim.

The pairs are made from the shared photos by the generators of this package with one seed, so
the same code makes the same pairs; the matcher that answers may come from another source tree
(``--tree``: an older commit checked out elsewhere), each worker importing ``scalematch`` from
it. Which runs are in the CI slice (``--slice ci``, about 3 minutes) is fixed here too.

A benchmark, not a test: times are reported against the baseline's, never asserted.
``scalematch lab regress --help``; docs/REGRESS.md says when to run it and how to read it.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import math
import multiprocessing as mp
import os
import platform
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, Iterator, List, Optional, Sequence, Set, Tuple

import click
import numpy as np

from ..geometry import as_matrix3
from .datasets import SharedDataMissing, list_photos, other_scene, require_shared, scene_of
from .evaluation import SUCCESS_PX
from .synthetic import (FLAT_KINDS, FLAT_RATIOS, OBLIQUE_CASES, SPREADS, TILTS, high_size_for,
                        make_flat_pair, make_oblique_pair, make_perspective_pair,
                        make_tilted_pair, make_zoom_pair, pair_rng)

#: The baseline the gate compares with, relative to the repository root
BASELINE = Path("tests") / "regress" / "baseline.json"
#: The one seed of every pair of the gate
SEED = 0
#: Kinds of run, in the order of the table
KINDS = ("zoom", "flat", "padded", "occluded", "partial", "relit", "tilted", "steep", "oblique",
         "perspective", "oxford", "oxford-zoom", "ef", "3d-pairs", "null-unrelated",
         "null-same-photo", "null-padded", "null-occluded")
#: An answer whose error differs from its baseline's by more than this (px) has moved
MOVED_PX = 1e-3
#: Kinds whose every run is a null (any claim is wrong)
NULL_KINDS = ("null-unrelated", "null-same-photo", "null-padded", "null-occluded")
#: Named slices: the kinds each runs (the CI slice: the synthetic zoom pairs, both crop kinds)
SLICES = {"ci": ("zoom", "flat")}

# The sample: how many photos per stratum. Photos (sorted by name) are spread evenly over the
# list with an offset per stratum, so each kind sees many scenes and each stratum others.
#: zoom pairs: ratios, and photos per ratio
ZOOM_RATIOS = (2.0, 3.0, 4.0, 6.0, 8.0, 10.0, 12.0, 16.0)
ZOOM_PER_RATIO = 5
#: flat pairs: photos per (ratio, flat kind) of ``FLAT_RATIOS`` x ``FLAT_KINDS``
FLAT_PER_CELL = 3
#: realistic kinds: ratios (EVALUATION.md: 2 to 8) and photos per (kind, ratio)
REALISTIC_RATIOS = (2.0, 3.0, 4.0, 6.0, 8.0)
REALISTIC_PER_RATIO = 3
#: tilted (t 1.41-4) and steep (t 6, 8) pairs: ratios, photos per (ratio, tilt)
TILTED_RATIOS = (2.0, 4.0)
STEEP_TILTS = (6.0, 8.0)
TILTED_PER_CELL = 2
STEEP_PER_CELL = 3
#: oblique pairs: photos per (ratio, tilt) case of ``OBLIQUE_CASES``; perspective pairs: photos
#: per (ratio, spread)
OBLIQUE_PER_CASE = 3
PERSPECTIVE_PER_CELL = 3
#: Oxford: the sequences with the homography model (every pair, both directions), and the
#: sequences with a zoom (EVALUATION.md) at these shrinks, ``OXFORD_ZOOM_PER_SHRINK`` of
#: img2..img6 per sequence and shrink
OXFORD = ("boat", "graf", "wall")
OXFORD_ZOOM_SEQUENCES = ("bikes", "trees", "leuven", "ubc", "boat", "graf", "wall")
OXFORD_ZOOM_SHRINKS = (2.0, 4.0, 8.0)
OXFORD_ZOOM_PER_SHRINK = 2
#: null pairs: the first of ``lab.nulls``' balanced order (unrelated and same-photo
#: interleaved), and unrelated pairs on canvases or with an occluder
NULLS = 80
NULLS_CHANGED = 16


@dataclass(frozen=True)
class Case:
    """One pair of the gate as it is given to the matcher, with what judges its answer."""

    kind: str  #: one of ``KINDS``
    name: str  #: unique within the kind and order
    order: str  #: "given" (the coarser image first) or "swapped"
    low: np.ndarray = field(repr=False)  #: the image given first
    high: np.ndarray = field(repr=False)  #: the image given second
    #: finer px -> coarser px (3x3); None for a null pair or a 3-D pair
    truth: Optional[np.ndarray] = field(repr=False, default=None)
    model: str = "similarity"  #: the configuration's model
    #: ef and 3-D pairs: the clicked points or the reference's sample, x_A, y_A, x_B, y_B
    #: (N, 4), A the image given first in the order "given"
    points: Optional[np.ndarray] = field(repr=False, default=None)

    @property
    def id(self) -> str:
        return f"{self.kind}|{self.name}|{self.order}"


# --------------------------------------------------------------------------------------------
# The sample
# --------------------------------------------------------------------------------------------

def spread(n: int, count: int, offset: int) -> List[int]:
    """``count`` indices of ``range(n)`` spread evenly, starting at ``offset`` (mod n).

    >>> spread(38, 3, 5)
    [5, 18, 30]
    """
    return [(offset + (i * n) // count) % n for i in range(count)]


def _both(kind: str, name: str, low: np.ndarray, high: np.ndarray, truth: Optional[np.ndarray],
          model: str = "similarity") -> Iterator[Case]:
    """A pair in the given order (low coarser) and swapped (its truth still finer -> coarser)."""
    low = _u8(low)
    high = _u8(high)
    t = None if truth is None else as_matrix3(truth)
    yield Case(kind, name, "given", low, high, t, model)
    yield Case(kind, name, "swapped", high, low, t, model)


def _u8(image: np.ndarray) -> np.ndarray:
    """Whole grey levels 0..255 as float32: what an 8-bit file holds."""
    return np.clip(np.rint(np.asarray(image, np.float32)), 0, 255).astype(np.float32)


class Photos:
    """The shared photos by index, read once each (the few most recent kept)."""

    def __init__(self, paths: Sequence[Path], keep: int = 3) -> None:
        self.paths = list(paths)
        self._cache: Dict[int, np.ndarray] = {}
        self._keep = keep

    def __len__(self) -> int:
        return len(self.paths)

    def name(self, i: int) -> str:
        return self.paths[i % len(self.paths)].name

    def __getitem__(self, i: int) -> np.ndarray:
        from ..imageio import read_grey

        i %= len(self.paths)
        if i not in self._cache:
            if len(self._cache) >= self._keep:
                self._cache.pop(next(iter(self._cache)))
            self._cache[i] = read_grey(self.paths[i])
        return self._cache[i]


def zoom_cases(photos: Photos, shared: Path, want: Set[str]) -> Iterator[Case]:
    if "zoom" not in want:
        return
    for j, r in enumerate(ZOOM_RATIOS):
        for i in spread(len(photos), ZOOM_PER_RATIO, 5 * j):
            name = photos.name(i)
            z = make_zoom_pair(photos[i], r, pair_rng(SEED, name, r), high_size_for(r),
                               source=name)
            yield from _both("zoom", f"{name} x{r:g}", z.low, z.high, z.truth)


def flat_cases(photos: Photos, shared: Path, want: Set[str]) -> Iterator[Case]:
    if "flat" not in want:
        return
    cells = [(r, k) for r in FLAT_RATIOS for k in FLAT_KINDS]
    for j, (r, k) in enumerate(cells):
        for i in spread(len(photos), FLAT_PER_CELL, 7 * j + 3):
            name = photos.name(i)
            z = make_flat_pair(photos[i], r, k, pair_rng(SEED, f"{name} flat {k}", r),
                               source=name)
            yield from _both("flat", f"{name} x{r:g} {k}", z.low, z.high, z.truth)


def realistic_cases(photos: Photos, shared: Path, want: Set[str]) -> Iterator[Case]:
    from . import realistic

    for k, kind in enumerate(realistic.KINDS):
        if kind not in want:
            continue
        for j, r in enumerate(REALISTIC_RATIOS):
            for i in spread(len(photos), REALISTIC_PER_RATIO, 11 * k + 4 * j + 1):
                name = photos.name(i)
                z = make_zoom_pair(photos[i], r, pair_rng(SEED, name, r), high_size_for(r),
                                   source=name)
                rng = pair_rng(SEED, f"{name} {kind}", r)
                if kind == "occluded":  # an occluder cut from the next photo (another scene)
                    q = realistic.occluded(z, photos[_other_scene(photos, i)], rng)
                else:
                    q = {"padded": realistic.padded, "partial": realistic.partial,
                         "relit": realistic.relit}[kind](z, rng)
                yield from _both(kind, f"{name} x{r:g}", q.low, q.high, q.truth)


def _other_scene(photos: Photos, i: int) -> int:
    """The first photo after ``i`` (cyclically) of another scene."""
    for k in range(1, len(photos)):
        if scene_of(photos.name(i + k)) != scene_of(photos.name(i)):
            return (i + k) % len(photos)
    return (i + 1) % len(photos)


def view_cases(photos: Photos, shared: Path, want: Set[str]) -> Iterator[Case]:
    """Tilted, steep, oblique and perspective pairs (exact affine or homography truth)."""
    sweeps = (("tilted", TILTED_RATIOS, TILTS, TILTED_PER_CELL, make_tilted_pair, "tilt", "t"),
              ("steep", TILTED_RATIOS, STEEP_TILTS, STEEP_PER_CELL, make_tilted_pair, "tilt",
               "t"),
              ("perspective", TILTED_RATIOS, SPREADS, PERSPECTIVE_PER_CELL,
               make_perspective_pair, "spread", "spread"))
    for s, (kind, ratios, values, per, make, key, short) in enumerate(sweeps):
        if kind not in want:
            continue
        cells = [(r, v) for r in ratios for v in values]
        for j, (r, v) in enumerate(cells):
            for i in spread(len(photos), per, 13 * s + 5 * j + 2):
                name = photos.name(i)
                p = make(photos[i], r, v, pair_rng(SEED, f"{name} {key} {v}", r), source=name)
                yield from _both(kind, f"{name} x{r:g} {short}{v:g}", p.low, p.high, p.truth)
    for j, (r, t) in enumerate(OBLIQUE_CASES if "oblique" in want else ()):
        for i in spread(len(photos), OBLIQUE_PER_CASE, 9 * j + 6):
            name = photos.name(i)
            p = make_oblique_pair(photos[i], r, t, pair_rng(SEED, f"{name} oblique {t}", r),
                                  source=name)
            yield from _both("oblique", f"{name} x{r:g} oblique t{t:g}", p.low, p.high, p.truth)


def oxford_cases(photos: Photos, shared: Path, want: Set[str]) -> Iterator[Case]:
    """Oxford img1 against img2..img6 with the homography model, and with a zoom."""
    from ..imageio import read_grey
    from .realistic import oxford_zoom

    root = shared / "data" / "oxford"
    for seq in OXFORD if "oxford" in want else ():
        if not (root / seq / "img1.png").is_file():
            continue
        img1 = read_grey(root / seq / "img1.png")
        for n in range(2, 7):
            h = np.loadtxt(root / seq / f"H1to{n}p").reshape(3, 3)
            yield from _both("oxford", f"{seq} 1->{n}", read_grey(root / seq / f"img{n}.png"),
                             img1, h / h[2, 2], "homography")
    for s, seq in enumerate(OXFORD_ZOOM_SEQUENCES if "oxford-zoom" in want else ()):
        if not (root / seq / "img1.png").is_file():
            continue
        img1 = read_grey(root / seq / "img1.png")
        for j, k in enumerate(OXFORD_ZOOM_SHRINKS):
            for n in spread(5, OXFORD_ZOOM_PER_SHRINK, s + 2 * j):
                n += 2
                h1n = np.loadtxt(root / seq / f"H1to{n}p").reshape(3, 3)
                low, high, truth = oxford_zoom(img1, read_grey(root / seq / f"img{n}.png"),
                                               h1n, k)
                yield from _both("oxford-zoom", f"{seq} 1->{n} /{k:g}", low, high, truth)


def ef_cases(photos: Photos, shared: Path, want: Set[str]) -> Iterator[Case]:
    """The real 3-D pairs with the fundamental matrix, A given first and B given first."""
    from .efpairs import ef_folder, load_pair, pair_names

    folder = ef_folder(shared)
    if folder is None or "ef" not in want:
        return
    for name in pair_names(folder):
        p = load_pair(folder, name)
        pts = np.asarray(p.points, np.float64)
        yield Case("ef", name, "given", _u8(p.a), _u8(p.b), None, "fundamental", pts)
        yield Case("ef", name, "swapped", _u8(p.b), _u8(p.a), None, "fundamental", pts)


def threed_cases(photos: Photos, shared: Path, want: Set[str]) -> Iterator[Case]:
    """The 3-D pairs of the multi-view photos with the fundamental matrix (``lab 3d-pairs``:
    each accepted reference pair with B and with A shrunk by 4), A given first and B given
    first, judged on the reference's sample of inliers as ef is on its clicked points."""
    from .threed import PHOTOS_SUBDIR, benchmark_pairs, load_images, read_references

    if "3d-pairs" not in want:
        return
    for pair in benchmark_pairs(read_references()):
        p = load_images(shared / PHOTOS_SUBDIR, pair)
        pts = np.asarray(p.points, np.float64)
        name = pair.name  # the label and the kind
        yield Case("3d-pairs", name, "given", _u8(p.a), _u8(p.b), None, "fundamental", pts)
        yield Case("3d-pairs", name, "swapped", _u8(p.b), _u8(p.a), None, "fundamental", pts)


def null_cases(photos: Photos, shared: Path, want: Set[str]) -> Iterator[Case]:
    """Null pairs: unrelated and same-photo (``lab.nulls``), then unrelated pairs on
    black-cornered canvases and with an occluder (``lab.realistic``)."""
    from . import realistic
    from .nulls import make_pair, null_specs
    from .synthetic import make_unrelated_pair

    names = [p.name for p in photos.paths]
    index = {n: i for i, n in enumerate(names)}
    for spec in null_specs(names, seed=SEED)[:NULLS]:
        kind = "null-unrelated" if spec.kind == "unrelated" else "null-same-photo"
        if kind not in want:
            continue
        pair = make_pair(spec, lambda n: photos[index[n]])
        yield from _both(kind, spec.pair_id, pair.low, pair.high, None)
    for c, kind in enumerate(("null-padded", "null-occluded")):
        if kind not in want:
            continue
        for j, i in enumerate(spread(len(photos), NULLS_CHANGED, 3 * c + 1)):
            other = _other_scene(photos, i + 5)
            r = ZOOM_RATIOS[(j + c) % len(ZOOM_RATIOS)]
            u = make_unrelated_pair(photos[i], photos[other], r,
                                    pair_rng(SEED, f"{names[i]} / {names[other]}", r),
                                    high_size_for(r), source_low=names[i],
                                    source_high=names[other])
            rng = pair_rng(SEED, f"{names[i]} / {names[other]} {kind}", r)
            q = (realistic.padded_null(u, rng) if kind == "null-padded"
                 else realistic.occluded(u, photos[other_scene(
                     names, other, (names[i % len(names)], names[other]))], rng))
            yield from _both(kind, f"{names[i]} / {names[other]} x{r:g}", q.low, q.high, None)


def cases(shared: Path, kinds: Sequence[str] = KINDS) -> Iterator[Case]:
    """Every case of the gate of the ``kinds`` named, in a fixed order (only those are made)."""
    photos = Photos(list_photos(shared))
    want = set(kinds)
    for make in (null_cases, zoom_cases, flat_cases, realistic_cases, view_cases, oxford_cases,
                 ef_cases, threed_cases):
        yield from make(photos, shared, want)


# --------------------------------------------------------------------------------------------
# Running: worker processes that import scalematch from a source tree
# --------------------------------------------------------------------------------------------

_MATCH: Dict[str, Any] = {}


def configured(method: str, config_class: Any, set_path: Callable[..., Any]) -> Any:
    """The Config of ``method``: a preset's name, then any ``+path=value`` settings as
    ``--set`` takes them (``tilt-4+views.max_short_side_px=500``)."""
    name, *settings = method.split("+")
    config = config_class.preset(name)
    for item in settings:
        path, _, value = item.partition("=")
        config = set_path(config, path, value)
    return config


def _init_worker(tree: Optional[str], preset: str = "default") -> None:
    """Import ``scalematch`` from ``tree`` (None: as installed) in this worker, one OpenCV
    thread (the workers share the cores); the configuration of every similarity run is
    ``preset`` (:func:`configured`)."""
    import importlib

    import cv2

    cv2.setNumThreads(1)
    if tree:
        this = sys.modules[__name__]  # the jobs name this module's functions: keep it
        for name in [m for m in sys.modules if m == "scalematch" or m.startswith("scalematch.")]:
            del sys.modules[name]
        sys.path.insert(0, tree)
    _MATCH["match"] = importlib.import_module("scalematch.pipeline").match
    _MATCH["Config"] = importlib.import_module("scalematch.config").Config
    # set_path where every tree has it, older ones too (this one re-exports it from options)
    _MATCH["config"] = _MATCH["Config"]() if preset == "default" else configured(
        preset, _MATCH["Config"], importlib.import_module("scalematch.cli").set_path)
    if tree:
        sys.modules[__name__] = this
    _MATCH["source"] = str(Path(importlib.import_module("scalematch").__file__).parent.parent)


def _run(job: Tuple[str, np.ndarray, np.ndarray, str]) -> Dict[str, Any]:
    """One match: its answer as plain values (the judge runs in the parent)."""
    case_id, low, high, model = job
    config = _MATCH["config"]
    if model != config.model:
        config = dataclasses.replace(config, model=model)
    t0 = time.perf_counter()
    try:
        r = _MATCH["match"](low, high, config)
    except Exception as exc:  # noqa: BLE001 - a crash is recorded as a failure, not a claim
        return {"id": case_id, "matched": False, "reason": f"error: {type(exc).__name__}: {exc}",
                "seconds": time.perf_counter() - t0, "source": _MATCH["source"]}
    seconds = time.perf_counter() - t0
    return {"id": case_id, "matched": bool(r.matched), "seconds": seconds,
            "transform": None if not r.matched else np.asarray(r.transform, float).tolist(),
            "order": str(getattr(r.order, "value", r.order)), "model": str(r.model),
            "inliers": int(r.n_inliers), "reason": r.reason or "", "source": _MATCH["source"]}


def judge(case: Case, answer: Dict[str, Any]) -> Dict[str, Any]:
    """The row of one run: solved, wrong, error (px) and what the matcher said."""
    from .efpairs import SOLVED_PX, a_to_b, symmetric_epipolar_error
    from .evaluation import reprojection_error
    from .realpairs import Pair, canonical

    # a 3-D pair answered with a plane map (no parallax seen) claims no epipolar geometry
    claimed = bool(answer["matched"]) and (case.points is None
                                           or answer.get("model") == "fundamental")
    err = math.nan
    if claimed and case.points is not None:
        f = a_to_b(np.asarray(answer["transform"]), answer["order"], case.order == "given")
        err = symmetric_epipolar_error(f, case.points)
        solved = err < SOLVED_PX
    elif claimed and case.truth is not None:
        swapped = case.order == "swapped"
        pair = Pair(case.kind, case.name, case.low, case.high, case.truth, swapped, case.model)
        est = canonical(pair, np.asarray(answer["transform"]), answer["order"] == "given")
        src, dst = (case.low, case.high) if swapped else (case.high, case.low)
        err = reprojection_error(est, case.truth, src.shape, dst.shape)
        solved = err < SUCCESS_PX
    else:
        solved = False
    return {"id": case.id, "kind": case.kind, "solved": bool(solved),
            "wrong": bool(claimed and not solved), "claimed": claimed,
            "error_px": None if not math.isfinite(err) else round(float(err), 4),
            "seconds": round(float(answer["seconds"]), 3), "inliers": answer.get("inliers", 0),
            "model": answer.get("model", ""), "reason": answer.get("reason", "")}


def run_cases(all_cases: Iterable[Case], jobs: int = 2, tree: Optional[str] = None,
              log: Callable[[str], None] = lambda s: None,
              preset: str = "default") -> Tuple[List[Dict[str, Any]], str]:
    """Run every case on ``jobs`` worker processes importing scalematch from ``tree``, with
    the configuration ``preset`` (:func:`configured`); the rows (in the cases' order) and the
    source folder the workers imported."""
    ctx = mp.get_context("spawn")  # not fork: a forked OpenCV thread pool can hang
    by_id: Dict[str, Case] = {}

    def jobs_of() -> Iterator[Tuple[str, np.ndarray, np.ndarray, str]]:
        for c in all_cases:
            by_id[c.id] = c
            yield c.id, c.low, c.high, c.model

    rows: Dict[str, Dict[str, Any]] = {}
    order: List[str] = []
    source = ""
    t0 = time.perf_counter()
    with ctx.Pool(jobs, initializer=_init_worker, initargs=(tree, preset)) as pool:
        for answer in pool.imap_unordered(_run, jobs_of()):
            case = by_id.pop(answer["id"])
            source = answer["source"]
            row = judge(case, answer)
            rows[row["id"]] = row
            order.append(row["id"])
            if row["wrong"]:
                log(f"  wrong claim: {row['id']} ({row['error_px']} px)")
            if len(rows) % 20 == 0:
                log(f"  {len(rows)} runs, {time.perf_counter() - t0:.0f} s")
    ids = sorted(rows, key=lambda i: (KINDS.index(rows[i]["kind"]), i))
    return [rows[i] for i in ids], source


# --------------------------------------------------------------------------------------------
# The comparison
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class KindReport:
    """One line of the gate's table."""

    kind: str
    runs: int
    solved: int
    base_solved: int  #: solved in the baseline, of the same runs
    lost: Tuple[str, ...]  #: ids solved in the baseline, not now
    gained: Tuple[str, ...]  #: ids solved now, not in the baseline
    wrong: int  #: wrong claims now
    new_wrong: Tuple[str, ...]  #: wrong now, not in the baseline
    #: runs whose answer moved: claimed in one and not the other, or an error that differs by
    #: more than ``MOVED_PX`` (a change meant to keep the answers has none)
    moved: int
    median_error: float  #: of the runs solved now, px
    base_median_error: float
    median_s: float  #: of every run now
    base_median_s: float
    unmatched: int  #: runs with no baseline row


def _median(values: Sequence[float]) -> float:
    return float(np.median(values)) if len(values) else math.nan


def compare(rows: Sequence[Dict[str, Any]],
            baseline: Dict[str, Dict[str, Any]]) -> List[KindReport]:
    """Per kind: solved, lost, gained, wrong claims (and new ones), median error and time,
    each against the baseline's rows of the same ids."""
    out = []
    for kind in KINDS:
        now = [r for r in rows if r["kind"] == kind]
        if not now:
            continue
        base = [baseline[r["id"]] for r in now if r["id"] in baseline]
        b = {r["id"]: r for r in base}
        lost = tuple(r["id"] for r in now if r["id"] in b and b[r["id"]]["solved"]
                     and not r["solved"])
        gained = tuple(r["id"] for r in now if r["id"] in b and r["solved"]
                       and not b[r["id"]]["solved"])
        new_wrong = tuple(r["id"] for r in now if r["wrong"]
                          and not (r["id"] in b and b[r["id"]]["wrong"]))
        moved = sum(_moved(r, b[r["id"]]) for r in now if r["id"] in b)
        out.append(KindReport(
            kind, len(now), sum(r["solved"] for r in now), sum(r["solved"] for r in base),
            lost, gained, sum(r["wrong"] for r in now), new_wrong, moved,
            _median([r["error_px"] for r in now if r["solved"]]),
            _median([r["error_px"] for r in base if r["solved"]]),
            _median([r["seconds"] for r in now]), _median([r["seconds"] for r in base]),
            sum(r["id"] not in b for r in now)))
    return out


def _moved(now: Dict[str, Any], base: Dict[str, Any]) -> bool:
    """Whether a run's answer differs from its baseline's (claim, or error beyond MOVED_PX)."""
    if now["claimed"] != base["claimed"]:
        return True
    a, b = now.get("error_px"), base.get("error_px")
    if a is None or b is None:
        return (a is None) != (b is None)
    return abs(a - b) > MOVED_PX


def _f(v: float, spec: str) -> str:
    return "-" if not math.isfinite(v) else format(v, spec)


def table(reports: Sequence[KindReport]) -> str:
    """The gate's table, one line per kind and a total."""
    head = ("| kind | runs | solved | baseline | lost | gained | wrong | new wrong | moved "
            "| median error px | baseline | median s | baseline | time ratio |")
    lines = [head, "|" + "---|" * 14]
    for k in reports:
        ratio = k.median_s / k.base_median_s if k.base_median_s > 0 else math.nan
        lines.append(f"| {k.kind} | {k.runs} | {k.solved} | {k.base_solved} | {len(k.lost)} | "
                     f"{len(k.gained)} | {k.wrong} | {len(k.new_wrong)} | {k.moved} | "
                     f"{_f(k.median_error, '.3f')} | {_f(k.base_median_error, '.3f')} | "
                     f"{_f(k.median_s, '.2f')} | {_f(k.base_median_s, '.2f')} | "
                     f"{_f(ratio, '.2f')} |")
    lines.append(f"| all | {sum(k.runs for k in reports)} | {sum(k.solved for k in reports)} | "
                 f"{sum(k.base_solved for k in reports)} | {sum(len(k.lost) for k in reports)} | "
                 f"{sum(len(k.gained) for k in reports)} | {sum(k.wrong for k in reports)} | "
                 f"{sum(len(k.new_wrong) for k in reports)} | {sum(k.moved for k in reports)} "
                 f"| | | | | |")
    return "\n".join(lines)


def summary(rows: Sequence[Dict[str, Any]], meta: Dict[str, Any]) -> str:
    """A run's own table (the baseline's, on the results page): per kind, runs, solved, wrong
    claims, the median error of the solved and the median time, with where it was made."""
    lines = [f"Made on {meta.get('commit', '?')} ({meta.get('date', '?')}, "
             f"{meta.get('machine', '?')}, {meta.get('jobs', '?')} workers, load "
             f"{meta.get('load', '?')}): `{meta.get('command', 'scalematch lab regress')}`, "
             f"{len(rows)} runs in {meta.get('minutes', '?')} minutes.", "",
             "| kind | runs | solved | wrong claims | median error px | median s |",
             "|---|---:|---:|---:|---:|---:|"]
    for kind in KINDS:
        rs = [r for r in rows if r["kind"] == kind]
        if rs:
            lines.append(f"| {kind} | {len(rs)} | {sum(r['solved'] for r in rs)} | "
                         f"{sum(r['wrong'] for r in rs)} | "
                         f"{_f(_median([r['error_px'] for r in rs if r['solved']]), '.3f')} | "
                         f"{_f(_median([r['seconds'] for r in rs]), '.2f')} |")
    lines.append(f"| all | {len(rows)} | {sum(r['solved'] for r in rows)} | "
                 f"{sum(r['wrong'] for r in rows)} | | |")
    return "\n".join(lines) + "\n"


def failures(reports: Sequence[KindReport]) -> List[str]:
    """What fails the gate: each lost run and each new wrong claim, one line each."""
    out = [f"lost: {i}" for k in reports for i in k.lost]
    out += [f"new wrong claim: {i}" for k in reports for i in k.new_wrong]
    return out


# --------------------------------------------------------------------------------------------
# The baseline file
# --------------------------------------------------------------------------------------------

def read_baseline(path: Path) -> Tuple[Dict[str, Any], Dict[str, Dict[str, Any]]]:
    """(meta, rows by id) of a baseline file; empty when there is none."""
    if not path.is_file():
        return {}, {}
    data = json.loads(path.read_text())
    return data.get("meta", {}), {r["id"]: r for r in data.get("rows", [])}


def write_baseline(path: Path, meta: Dict[str, Any], rows: Sequence[Dict[str, Any]]) -> None:
    """The baseline as JSON with one row per line (a readable diff when it changes)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = sorted(rows, key=lambda r: (KINDS.index(r["kind"]) if r["kind"] in KINDS else 99,
                                       r["id"]))
    body = ",\n".join("  " + json.dumps(r, sort_keys=True) for r in rows)
    path.write_text('{"meta": ' + json.dumps(meta, sort_keys=True) + ',\n "rows": [\n'
                    + body + "\n]}\n")


def _git(tree: Path, *args: str) -> str:
    import subprocess

    try:
        return subprocess.run(["git", "-C", str(tree), *args], capture_output=True, text=True,
                              timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


# --------------------------------------------------------------------------------------------
# The command
# --------------------------------------------------------------------------------------------

@click.command("regress", context_settings={"help_option_names": ["-h", "--help"],
                                             "max_content_width": 100})
@click.option("--shared", type=click.Path(file_okay=False, path_type=Path),
              help="The shared folder (default: ../shared beside the repo, or "
                   "$SCALEMATCH_SHARED).")
@click.option("--slice", "slice_", type=click.Choice(sorted(SLICES)),
              help="Run only this slice (ci: the synthetic zoom pairs, about 3 minutes).")
@click.option("--kinds", default="", help="Comma-separated kinds to run (default: every kind).")
@click.option("--tree", type=click.Path(file_okay=False, exists=True, path_type=Path),
              help="Import the matcher from this source tree (an older commit checked out "
                   "with `git worktree add`) instead of the installed one.")
@click.option("--baseline", "baseline_path", type=click.Path(dir_okay=False, path_type=Path),
              default=BASELINE, show_default=True, help="The baseline file.")
@click.option("--update", is_flag=True,
              help="Write this run's rows into the baseline (after a change is accepted; "
                   "the commit says why).")
@click.option("--rows", "rows_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Also write this run's rows here (the baseline's format).")
@click.option("--jobs", type=click.IntRange(min=1), default=2, show_default=True,
              help="Worker processes (one OpenCV thread each).")
@click.option("--if-shared", is_flag=True,
              help="Without the shared folder, say so and exit 0 (for CI runs elsewhere).")
@click.option("--preset", default="default", show_default=True,
              help="The configuration: a Config preset, with values set as +path=value "
                   "(tilt-4+views.max_short_side_px=500): a design's gate against "
                   "the default's baseline.")
@click.option("--write-doc", type=click.Path(dir_okay=False, path_type=Path),
              help="With --update: write the new baseline's table into this Markdown file "
                   "(its regress section; make regress UPDATE=1 writes docs/REGRESS.md).")
def regress_command(shared, slice_, kinds, tree, baseline_path, update, rows_path, jobs,
                    if_shared, preset, write_doc):
    """The regression gate: a fixed sample of every kind of pair, both orders, against the
    committed baseline. Exit 1 on any run lost or new wrong claim.

    \b
    Examples:
      make regress                      # every kind, 7 minutes on 2 quiet cores
      make regress SLICE=ci             # the zoom pairs, 1 to 3 minutes
      make regress UPDATE=1             # accept this run as the new baseline
      git worktree add /tmp/old 333305c && scalematch lab regress --tree /tmp/old
    """
    wanted = list(SLICES[slice_]) if slice_ else list(KINDS)
    if kinds:
        wanted = [k.strip() for k in kinds.split(",") if k.strip()]
        for k in wanted:
            if k not in KINDS:
                raise click.BadParameter(f"unknown kind {k!r}; one of {', '.join(KINDS)}",
                                         param_hint="--kinds")
    if preset != "default":  # a preset or a setting that does not exist: said before the run
        from ..config import Config
        from ..options import set_path

        try:
            configured(preset, Config, set_path)
        except (KeyError, ValueError, TypeError, click.ClickException) as exc:
            raise click.BadParameter(str(exc), param_hint="--preset") from None
    try:
        shared = require_shared(shared)
    except SharedDataMissing as exc:
        if if_shared:
            click.echo(f"regress: skipped: {exc.message}", err=True)
            return
        raise
    log = lambda s: click.echo(s, err=True)
    meta_old, baseline = read_baseline(baseline_path)
    # the code as it is when the workers import it (a commit made during the run is not it)
    src = Path(tree) if tree else Path(__file__).resolve().parents[2]
    commit = _git(src, "rev-parse", "--short", "HEAD")
    dirty = bool(_git(src, "status", "--porcelain", "--untracked-files=no"))
    t0 = time.perf_counter()
    log(f"regress: {', '.join(wanted)}; {jobs} workers; matcher from "
        f"{tree or 'the installed scalematch'}; configuration {preset}")
    rows, source = run_cases(cases(Path(shared), wanted), jobs, str(tree) if tree else None, log,
                             preset)
    wall = time.perf_counter() - t0
    reports = compare(rows, baseline)
    click.echo(f"\nregress: {len(rows)} runs in {wall / 60:.1f} min, matcher {commit or '?'}"
               f"{' (with uncommitted changes)' if dirty else ''} from {source}; baseline "
               f"{meta_old.get('commit', 'none')} of {meta_old.get('date', '-')}\n")
    click.echo(table(reports))
    meta = {"commit": commit + ("+" if dirty else ""),
            "date": _dt.datetime.now().strftime("%Y-%m-%d %H:%M"),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores", "jobs": jobs,
            "minutes": round(wall / 60, 1),
            "load": " ".join(f"{v:.1f}" for v in os.getloadavg()),
            "command": "scalematch lab regress" + "".join(
                f" {a}" for a in sys.argv[3:] if a not in ("--update",) and not a.endswith(".md")
                and a != "--write-doc")}
    if rows_path is not None:
        write_baseline(rows_path, meta, rows)
    bad = failures(reports)
    if update:
        merged = dict(baseline)
        merged.update({r["id"]: r for r in rows})
        write_baseline(baseline_path, meta, list(merged.values()))
        click.echo(f"\nwrote {len(rows)} runs into {baseline_path}"
                   f"{f' ({len(bad)} lost or new wrong accepted)' if bad else ''}")
        if write_doc is not None:
            from .realpairs import write_section

            write_section(write_doc, summary(list(merged.values()), meta), "regress",
                          "make regress UPDATE=1")
            click.echo(f"wrote {write_doc}")
        return
    if bad:
        click.echo("\nThe gate fails:\n" + "\n".join(f"  {b}" for b in bad))
        sys.exit(1)
    if not baseline:
        click.echo(f"\nno baseline at {baseline_path}: nothing compared "
                   "(make regress UPDATE=1 writes it)")
        return
    click.echo("\nThe gate passes: no run lost, no new wrong claim.")
