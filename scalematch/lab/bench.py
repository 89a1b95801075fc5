"""The benchmark: scalematch against OpenCV's SIFT, ORB, AKAZE and BRISK on the same pairs.

Everything follows EVALUATION.md. The pairs, made once per run and shared by every method:

* synthetic zoom pairs cut from ``shared/data/photos`` (``synthetic.pairs_from_photos``) at each
  ratio, with exact ground truth;
* unrelated pairs: the low image of one photo against the high image of a photo of another
  scene (scene = file name prefix before the first ``_``); any match claimed is false;
* the real boat sequence, high = img1, low = img2..img6, truth the homography H1toNp;
* one pair whose high image is 6000x4000 px (time and memory at camera resolution).

A method is a callable ``(low, high) -> (transform or None, info dict)``; ``transform`` maps a
high pixel to a low pixel. Each method runs in its own fresh worker process (multiprocessing,
spawn), one method at a time, so timings are not contended and memory is measured per method:
the peak resident set size of the worker minus its resident size just before the first pair,
after the imports and a warm-up call on a tiny image (so one-off library initialisation is not
counted). Pairs are read one at a time from ``.npz`` files in the output folder, so the figure
includes the few MB of the pair being matched (its float32 copy) but not the other pairs.

Run ``python -m scalematch.lab.bench --help``. A benchmark, not a test: nothing here asserts a time.
"""

from __future__ import annotations

import csv
import datetime as _dt
import functools
import json
import math
import multiprocessing as mp
import os
import platform
import resource
import shlex
import shutil
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import click
import cv2
import numpy as np

from .baselines import BASELINES, MIN_INLIERS, make_detector, match_baseline
from .datasets import boat_pairs, find_shared, list_photos, require_shared, scene_of
from .evaluation import SUCCESS_PX, is_success, reprojection_error, similarity_floor
from ..geometry import similarity_parts
from ..imageio import read_grey
from ..result import to_jsonable
from .synthetic import (CROP_PICKS, ZoomPair, pairs_from_photos, unrelated_indices,
                        zoom_pair_from_crop)

#: Ratios of the synthetic pairs (EVALUATION.md step 4).
RATIOS = (2, 3, 4, 6, 8, 10, 12, 16)
#: scalematch configurations by name: the two modes, and the ablation steps from the paper's
#: method to the default (``--methods`` takes any of them; docs/results/ABLATION.md reports what
#: each step bought). Values: (one-line description, name of the preset in ``config.PRESETS``).
VARIANTS: Dict[str, Tuple[str, str]] = {
    "scalematch": ("the default", "default"),
    "scalematch-paper": ("the paper: jets, Mahalanobis, semi-local constraints, scales 1-8",
                         "paper"),
    "paper-finer-scales": ("the paper's pipeline on the default's scales (1-12.7, third octaves)",
                           "paper-finer-scales"),
    "default-paper-scales": ("the default's descriptors and constraints on the paper's scales "
                             "1-8, every scale run", "default-paper-scales"),
    "default-no-probe": ("the default, every scale run (no probe)", "default-no-probe"),
    "default-quarter-octaves": ("the default on 15 scales 1-11.3 (quarter octaves)",
                                "default-quarter-octaves"),
    "default-no-rotation-check": ("the default without the rotation-consistency filter",
                                  "default-no-rotation-check"),
}
#: The default run: the two modes and the peers, in the order they are reported.
METHOD_NAMES = ("scalematch", "scalematch-paper") + BASELINES
#: Every name ``--methods`` accepts.
ALL_METHODS = METHOD_NAMES + tuple(v for v in VARIANTS if v not in METHOD_NAMES)
#: The reference every time is divided by (EVALUATION.md: OpenCV SIFT).
REFERENCE = "sift"
#: Unrelated pairs (false-match test).
UNRELATED_COUNT = 50
#: Pairs in the batch timed with 1 and ``jobs`` worker processes.
BATCH_SIZE = 40
#: Methods whose batch throughput is timed (when selected): the project and its reference.
BATCH_METHODS = ("scalematch", REFERENCE)
#: Size (width, height) of the camera-resolution high image, px.
LARGE_SIZE = (6000, 4000)
#: Ratio of the camera-resolution pair: 6000x4000 / 10 = 600x400 px, whose rotated footprint
#: (at most 721 px tall) fits in the 1024x768 low image at every angle.
LARGE_RATIO = 10.0
#: Model the methods fit on the boat pairs: its truth is a homography, and on boat 1->6 even
#: the best similarity is 3.9 px off (``evaluation.similarity_floor``), so EVALUATION.md's
#: "use the homography model" is followed. Synthetic pairs use the similarity model.
BOAT_MODEL = "homography"
#: Stream numbers separating the seeded draws of the run (unrelated pairs, the large pair).
_UNRELATED_STREAM, _LARGE_STREAM = 1, 2

Method = Callable[[np.ndarray, np.ndarray], Tuple[Optional[np.ndarray], Dict[str, Any]]]
PathLike = Union[str, Path]


# --------------------------------------------------------------------------------------------
# Methods
# --------------------------------------------------------------------------------------------

def scalematch_method(low: np.ndarray, high: np.ndarray, mode: str = "default", seed: int = 0,
                      model: str = "similarity") -> Tuple[Optional[np.ndarray], Dict[str, Any]]:
    """scalematch's ``pipeline.match`` with the configuration named ``mode`` (VARIANTS;
    "default" and "paper" stand for "scalematch" and "scalematch-paper")."""
    from ..config import Config
    from ..pipeline import match

    name = {"default": "scalematch", "paper": "scalematch-paper"}.get(mode, mode)
    config = Config.preset(VARIANTS[name][1], seed=seed, model=model)
    r = match(low, high, config)
    return (r.transform if r.matched else None), {"inliers": r.n_inliers, "reason": r.reason}


def baseline_method(low: np.ndarray, high: np.ndarray, name: str = REFERENCE, seed: int = 0,
                    model: str = "similarity") -> Tuple[Optional[np.ndarray], Dict[str, Any]]:
    """An OpenCV baseline (``baselines.match_baseline``)."""
    r = match_baseline(low, high, name, model=model, seed=seed)
    return r.transform, {"inliers": r.inliers, "matches": r.matches}


def make_method(name: str, seed: int = 0, model: str = "similarity") -> Method:
    """The callable of method ``name`` (see METHOD_NAMES) fitting ``model``.

    Raises ``ImportError`` when the method's code is not available (e.g. ``scalematch.pipeline``
    not written yet) and ``ValueError`` for an unknown name.
    """
    if name in BASELINES:
        make_detector(name)  # fails early when this OpenCV build lacks the detector
        return functools.partial(baseline_method, name=name, seed=seed, model=model)
    if name in VARIANTS:
        import importlib

        try:
            importlib.import_module("scalematch.pipeline")
        except ImportError:
            raise
        except Exception as exc:  # a module being edited (SyntaxError, ...) counts as missing
            raise ImportError(f"scalematch.pipeline failed to import: {exc!r}") from exc
        return functools.partial(scalematch_method, mode=name, seed=seed, model=model)
    raise ValueError(f"unknown method {name!r}; choose from {', '.join(ALL_METHODS)}")


# --------------------------------------------------------------------------------------------
# Pairs, stored once per run and read by every worker
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class PairRecord:
    """One benchmark pair: where its images are stored and its ground truth."""

    kind: str  #: synthetic | unrelated | boat | large
    source: str  #: where low comes from
    high_source: str  #: where high comes from
    ratio: float  #: resolution ratio (of the low image's own pair for unrelated ones)
    angle_deg: float
    truth: Optional[np.ndarray] = field(repr=False)  #: high px -> low px; None when unrelated
    low_file: str = ""  #: .npz holding ``low`` (key "low")
    high_file: str = ""  #: .npz holding ``high`` (key "high")
    low_shape: Tuple[int, int] = (0, 0)
    high_shape: Tuple[int, int] = (0, 0)
    model: str = "similarity"  #: the model methods fit on this pair


def _store(folder: Path, name: str, low: np.ndarray, high: np.ndarray) -> str:
    """Write low (uint8: synthetic lows are 8-bit) and high (float32) to ``folder/name.npz``."""
    path = folder / f"{name}.npz"
    low_u8 = np.clip(np.rint(low), 0, 255).astype(np.uint8)
    low_out = low_u8 if np.array_equal(low_u8, low) else low.astype(np.float32)
    np.savez(path, low=low_out, high=high.astype(np.float32))
    return str(path)


def load_pair(rec: PairRecord) -> Tuple[np.ndarray, np.ndarray]:
    """(low, high) of ``rec`` as float32 grey arrays."""
    with np.load(rec.low_file) as z:
        low = z["low"].astype(np.float32)
    with np.load(rec.high_file) as z:
        high = z["high"].astype(np.float32)
    return low, high


def _record(kind: str, pair: ZoomPair, low_file: str, high_file: str) -> PairRecord:
    return PairRecord(kind=kind, source=pair.source, high_source=pair.high_source or pair.source,
                      ratio=pair.ratio, angle_deg=pair.angle_deg, truth=pair.truth,
                      low_file=low_file, high_file=high_file, low_shape=pair.low.shape,
                      high_shape=pair.high.shape)


def make_large_pair(photo_path: PathLike, seed: int, size: Tuple[int, int] = LARGE_SIZE,
                    ratio: float = LARGE_RATIO) -> ZoomPair:
    """A pair whose high image is ``size`` px: the photo upscaled (bicubic) and cut to size.

    The photo is enlarged by the smallest factor that covers ``size`` (``cv2.INTER_CUBIC``) and
    its centre ``size`` window is the high image; the low image is all of it, zoomed out by
    ``ratio`` as in EVALUATION.md step 2 (``synthetic.zoom_pair_from_crop``). The enlarged photo
    has less fine detail than a real 24 Mpx photo; the pair measures time and memory.
    """
    photo = read_grey(photo_path)
    w, h = int(size[0]), int(size[1])
    f = max(w / photo.shape[1], h / photo.shape[0], 1.0)
    big = cv2.resize(photo, (max(w, int(math.ceil(photo.shape[1] * f))),
                             max(h, int(math.ceil(photo.shape[0] * f)))),
                     interpolation=cv2.INTER_CUBIC)
    y0, x0 = (big.shape[0] - h) // 2, (big.shape[1] - w) // 2
    high = np.ascontiguousarray(np.clip(big[y0:y0 + h, x0:x0 + w], 0, 255))
    del big, photo
    rng = np.random.default_rng([int(seed), _LARGE_STREAM])
    name = f"{Path(photo_path).name} x{f:.3f} cut {w}x{h}"
    return zoom_pair_from_crop(high, (0, 0, w, h), ratio, rng, source=name)


def prepare_pairs(paths: Sequence[Path], ratios: Sequence[float], seed: int, folder: Path,
                  shared: Optional[Path], unrelated: int, boat: bool, large: bool,
                  log: Callable[[str], None], crop: str = "most") -> List[PairRecord]:
    """Make every pair of the run, store it under ``folder`` and return the records.

    Order: synthetic (photo by photo in ``paths`` order, ratio by ratio), unrelated, boat, large.
    """
    folder.mkdir(parents=True, exist_ok=True)
    records: List[PairRecord] = []
    t0 = time.perf_counter()
    for k, pair in enumerate(pairs_from_photos(paths, ratios, seed, pick=crop)):
        f = _store(folder, f"syn{k:04d}", pair.low, pair.high)
        records.append(_record("synthetic", pair, f, f))
    log(f"made {len(records)} synthetic pairs from {len(paths)} photos "
        f"in {time.perf_counter() - t0:.0f} s")
    syn = list(records)
    idx = unrelated_indices([r.source for r in syn], [r.ratio for r in syn], unrelated,
                            np.random.default_rng([int(seed), _UNRELATED_STREAM]), scene_of)
    for i, j in idx:
        a, b = syn[i], syn[j]
        records.append(PairRecord(kind="unrelated", source=a.source, high_source=b.source,
                                  ratio=a.ratio, angle_deg=a.angle_deg, truth=None,
                                  low_file=a.low_file, high_file=b.high_file,
                                  low_shape=a.low_shape, high_shape=b.high_shape))
    if unrelated and len(idx) < unrelated:
        log(f"note: only {len(idx)} unrelated pairs possible (photos of too few scenes)")
    if boat and shared is not None:
        for k, (low, high, h, name) in enumerate(boat_pairs(shared)):
            ratio, angle, _ = similarity_parts(h)
            f = _store(folder, f"boat{k}", low, high)
            records.append(PairRecord(kind="boat", source=name, high_source="boat img1",
                                      ratio=ratio, angle_deg=angle, truth=h, low_file=f,
                                      high_file=f, low_shape=low.shape, high_shape=high.shape,
                                      model=BOAT_MODEL))
    if large and paths:
        biggest = max(paths, key=lambda p: _pixels(p))
        pair = make_large_pair(biggest, seed)
        f = _store(folder, "large", pair.low, pair.high)
        records.append(_record("large", pair, f, f))
    return records


def _pixels(path: Path) -> int:
    """Pixel count of an image file without decoding it all (header only)."""
    img = cv2.imread(str(path), cv2.IMREAD_REDUCED_GRAYSCALE_8)
    return 0 if img is None else int(img.shape[0] * img.shape[1])


# --------------------------------------------------------------------------------------------
# Workers: one process per method; memory measured inside
# --------------------------------------------------------------------------------------------

def _rss_mb() -> float:
    """Current resident set size of this process, MB (Linux /proc; else the peak so far)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20
    except OSError:
        return _peak_mb()


def _reset_peak() -> bool:
    """Reset the kernel's peak-RSS mark of this process (Linux >= 4.0); False when impossible."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def _peak_mb() -> float:
    """Peak resident set size of this process, MB: VmHWM (honours ``_reset_peak``), else
    ``resource.getrusage(...).ru_maxrss`` (the lifetime peak)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2 ** 20 if sys.platform == "darwin" else peak / 1024.0


def _warm_up(method: Method) -> None:
    """One call on a tiny textured pair: imports and one-off library set-up happen here."""
    rng = np.random.default_rng(0)
    high = cv2.GaussianBlur(rng.uniform(0, 255, (96, 128)).astype(np.float32), (0, 0), 2.0)
    low = cv2.resize(high, (64, 48), interpolation=cv2.INTER_AREA)
    try:
        method(low, high)
    except Exception:  # noqa: BLE001 - the real pairs will report the error
        pass


def run_one(method: Method, rec: PairRecord) -> Dict[str, Any]:
    """Run ``method`` on one pair and judge it: one CSV row (a dict)."""
    low, high = load_pair(rec)
    reason = ""
    t0 = time.perf_counter()
    try:
        transform, info = method(low, high)
    except Exception as exc:  # noqa: BLE001 - a crash fails the pair, not the benchmark
        transform, info, reason = None, {}, f"error: {type(exc).__name__}: {exc}"
    seconds = time.perf_counter() - t0
    reason = reason or str(info.get("reason", ""))
    if rec.truth is not None:
        err = reprojection_error(transform, rec.truth, rec.high_shape, rec.low_shape)
        floor = similarity_floor(rec.truth, rec.high_shape, rec.low_shape)
    else:
        err = floor = math.nan
    return {"kind": rec.kind, "source": rec.source, "high_source": rec.high_source,
            "ratio": rec.ratio, "angle_deg": rec.angle_deg, "model": rec.model,
            "similarity_floor_px": floor, "claimed": transform is not None,
            "error_px": err, "success": bool(rec.truth is not None and is_success(err)),
            "seconds": seconds, "inliers": int(info.get("inliers", 0)),
            "matches": int(info.get("matches", -1)), "reason": reason,
            "transform": "" if transform is None else " ".join(
                f"{v:.6g}" for v in np.asarray(transform, float).ravel())}


def _worker_run(methods: Dict[str, Method],
                records: Sequence[PairRecord]) -> Tuple[List[Dict[str, Any]], float]:
    """In a fresh process: warm up, mark memory, run every record; (rows, peak MB increase).

    ``methods`` maps a model name to the method fitting it; each record uses its ``model``.
    """
    for method in methods.values():
        _warm_up(method)
    base = _rss_mb()
    reset = _reset_peak()
    rows = [run_one(methods[rec.model], rec) for rec in records]
    peak = _peak_mb()
    return rows, max(peak - base, 0.0) if reset or peak >= base else math.nan


_BATCH_METHOD: Optional[Method] = None


def _batch_init(method: Method, opencv_threads: int) -> None:
    global _BATCH_METHOD
    _BATCH_METHOD = method
    if opencv_threads:
        import cv2

        cv2.setNumThreads(opencv_threads)
    _warm_up(method)


def _batch_ready(_: int) -> int:
    time.sleep(0.3)  # every worker picks one: all started and warmed up before the clock runs
    return os.getpid()


def _batch_one(rec: PairRecord) -> bool:
    transform, _ = _BATCH_METHOD(*load_pair(rec))
    return transform is not None


def time_batch(method: Method, records: Sequence[PairRecord], workers: int) -> float:
    """Wall seconds to match ``records`` with ``workers`` spawned processes (after start-up).

    As ``scalematch batch`` does, several workers use one OpenCV thread each (the processes are
    the parallelism; scalematch's own threads follow OpenCV's count), every method alike; a
    single worker keeps OpenCV's default.
    """
    ctx = mp.get_context("spawn")
    threads = 1 if workers > 1 else 0
    with ctx.Pool(workers, initializer=_batch_init, initargs=(method, threads)) as pool:
        pool.map(_batch_ready, range(workers), chunksize=1)
        t0 = time.perf_counter()
        pool.map(_batch_one, list(records), chunksize=1)
        return time.perf_counter() - t0


def _in_fresh_process(fn, *args):
    ctx = mp.get_context("spawn")
    with ProcessPoolExecutor(max_workers=1, mp_context=ctx) as ex:
        return ex.submit(fn, *args).result()


# --------------------------------------------------------------------------------------------
# Summaries
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class RatioSummary:
    """One method at one ratio (synthetic pairs)."""

    method: str
    ratio: float
    pairs: int
    successes: int
    success_rate: float  #: successes / pairs
    median_error_px: float  #: over the successes (nan when none)
    median_seconds: float  #: per pair
    time_vs_reference: float  #: median_seconds / the reference's at this ratio (nan if absent)


@dataclass(frozen=True)
class MethodSummary:
    """One method over the whole run."""

    method: str
    pairs: int
    successes: int
    success_rate: float
    median_error_px: float
    median_seconds: float
    time_vs_reference: float
    peak_memory_mb: float  #: peak RSS increase of the worker over all pairs (see module doc)
    false_claims: int  #: matches claimed on unrelated pairs
    unrelated: int
    boat: Tuple[Tuple[str, float], ...]  #: (name, error px) per boat pair
    large_seconds: float = math.nan  #: the 6000x4000 pair
    large_memory_mb: float = math.nan
    large_error_px: float = math.nan
    batch_seconds: Tuple[Tuple[int, float], ...] = ()  #: (workers, wall seconds for the batch)


@dataclass(frozen=True)
class BenchReport:
    """Everything a run produced; ``table`` is the printed (Markdown) text."""

    per_ratio: Tuple[RatioSummary, ...]
    per_method: Tuple[MethodSummary, ...]
    rows: Tuple[Dict[str, Any], ...] = field(repr=False)
    settings: Dict[str, Any] = field(repr=False)
    skipped: Tuple[Tuple[str, str], ...]  #: (method, why)
    csv_path: Optional[Path]
    plot_path: Optional[Path]
    summary_path: Optional[Path]
    table: str = field(repr=False)


def _median(values: Sequence[float]) -> float:
    v = [x for x in values if x is not None and math.isfinite(x)]
    return float(np.median(v)) if v else math.nan


def summarise(rows: Sequence[Dict[str, Any]], methods: Sequence[str], ratios: Sequence[float],
              memory: Dict[str, float], large: Dict[str, Dict[str, float]],
              batch: Dict[str, Tuple[Tuple[int, float], ...]]
              ) -> Tuple[Tuple[RatioSummary, ...], Tuple[MethodSummary, ...]]:
    """Per (method, ratio) and per method summaries of the per-pair rows."""
    def syn(m, r=None):
        return [x for x in rows if x["method"] == m and x["kind"] == "synthetic"
                and (r is None or x["ratio"] == r)]

    ref_time = {r: _median([x["seconds"] for x in syn(REFERENCE, r)]) for r in ratios}
    ref_all = _median([x["seconds"] for x in syn(REFERENCE)])
    per_ratio, per_method = [], []
    for m in methods:
        for r in ratios:
            xs = syn(m, r)
            n_ok = sum(x["success"] for x in xs)
            t = _median([x["seconds"] for x in xs])
            per_ratio.append(RatioSummary(
                method=m, ratio=float(r), pairs=len(xs), successes=n_ok,
                success_rate=n_ok / len(xs) if xs else math.nan,
                median_error_px=_median([x["error_px"] for x in xs if x["success"]]),
                median_seconds=t, time_vs_reference=t / ref_time[r] if ref_time[r] else math.nan))
        xs = syn(m)
        n_ok = sum(x["success"] for x in xs)
        t = _median([x["seconds"] for x in xs])
        unrel = [x for x in rows if x["method"] == m and x["kind"] == "unrelated"]
        boats = tuple((x["source"], x["error_px"]) for x in rows
                      if x["method"] == m and x["kind"] == "boat")
        lg = large.get(m, {})
        per_method.append(MethodSummary(
            method=m, pairs=len(xs), successes=n_ok, success_rate=n_ok / len(xs) if xs else math.nan,
            median_error_px=_median([x["error_px"] for x in xs if x["success"]]),
            median_seconds=t, time_vs_reference=t / ref_all if ref_all else math.nan,
            peak_memory_mb=memory.get(m, math.nan),
            false_claims=sum(x["claimed"] for x in unrel), unrelated=len(unrel), boat=boats,
            large_seconds=lg.get("seconds", math.nan), large_memory_mb=lg.get("memory_mb", math.nan),
            large_error_px=lg.get("error_px", math.nan), batch_seconds=batch.get(m, ())))
    return tuple(per_ratio), tuple(per_method)


def pair_by_pair(rows: Sequence[Dict[str, Any]], methods: Sequence[str],
                 ours: str = "scalematch") -> str:
    """Markdown: for each other method, the synthetic pairs it solves and ``ours`` misses (and
    the other way round), named, so a rate that looks better cannot hide a pair lost."""
    if ours not in methods:
        return ""
    key = lambda x: (x["source"], float(x["ratio"]))  # noqa: E731
    solved = {m: {key(x) for x in rows if x["method"] == m and x["kind"] == "synthetic"
                  and x["success"]} for m in methods}
    out = [f"Pair by pair against {ours} (synthetic pairs; a pair is a photo and a ratio)", "",
           f"| method | solves, {ours} misses | {ours} solves, it misses |", "|---|---|---:|"]
    for m in methods:
        if m == ours:
            continue
        lost = sorted(solved[m] - solved[ours])
        names = ", ".join(f"{s} x{r:g}" for s, r in lost) or "none"
        out.append(f"| {m} | {len(lost)}: {names} | {len(solved[ours] - solved[m])} |")
    return "\n".join(out) + "\n"


def _fmt(v: float, spec: str = ".2f", none: str = "-") -> str:
    return none if v is None or not math.isfinite(v) else format(v, spec)


def format_tables(per_ratio: Sequence[RatioSummary], per_method: Sequence[MethodSummary],
                  ratios: Sequence[float], batch_size: int) -> str:
    """The report as Markdown tables (printed as is, and written to BENCHMARKS.md)."""
    rs = [float(r) for r in ratios]
    cell = {(s.method, s.ratio): s for s in per_ratio}
    head = "| method | " + " | ".join(f"x{r:g}" for r in rs) + " | all |"
    rule = "|---|" + "---:|" * (len(rs) + 1)
    out = [f"Success rate (error < {SUCCESS_PX:g} px), synthetic pairs: successes/pairs", "",
           head, rule]
    for m in per_method:
        cells = [f"{cell[m.method, r].successes}/{cell[m.method, r].pairs}" for r in rs]
        out.append(f"| {m.method} | " + " | ".join(cells)
                   + f" | {m.successes}/{m.pairs} ({_fmt(100 * m.success_rate, '.0f')}%) |")
    out += ["", "Median error of the successes, low-resolution px", "", head, rule]
    for m in per_method:
        out.append(f"| {m.method} | " + " | ".join(
            _fmt(cell[m.method, r].median_error_px) for r in rs) + f" | {_fmt(m.median_error_px)} |")
    out += ["", f"Median time per pair, s (and its ratio to {REFERENCE}'s)", "", head, rule]
    for m in per_method:
        out.append(f"| {m.method} | " + " | ".join(
            f"{_fmt(cell[m.method, r].median_seconds, '.3f')} "
            f"({_fmt(cell[m.method, r].time_vs_reference, '.1f')}x)" for r in rs)
            + f" | {_fmt(m.median_seconds, '.3f')} ({_fmt(m.time_vs_reference, '.1f')}x) |")
    boat_names = [n for n, _ in per_method[0].boat] if per_method else []
    out += ["", "Per method: peak memory, false matches, boat (error px, real zoom sequence, "
            f"{BOAT_MODEL} model), "
            f"the 6000x4000 pair, a batch of {batch_size} pairs", "",
            "| method | peak memory (MB) | false matches on unrelated pairs | "
            + " | ".join(boat_names) + (" | " if boat_names else "")
            + "6000x4000: s / MB / error px | batch: s (workers) |",
            "|---|---:|---:|" + "---:|" * len(boat_names) + "---:|---:|"]
    for m in per_method:
        boats = [(_fmt(e, ".2f", "none") + ("" if is_success(e) else " (fail)")) for _, e in m.boat]
        batch = ", ".join(f"{s:.1f} ({w})" for w, s in m.batch_seconds) or "-"
        out.append(f"| {m.method} | {_fmt(m.peak_memory_mb, '.0f')} | "
                   f"{m.false_claims}/{m.unrelated} | " + " | ".join(boats)
                   + (" | " if boats else "")
                   + f"{_fmt(m.large_seconds, '.1f')} / {_fmt(m.large_memory_mb, '.0f')} / "
                     f"{_fmt(m.large_error_px, '.2f', 'none')} | {batch} |")
    return "\n".join(out) + "\n"


def plot_success(per_ratio: Sequence[RatioSummary], methods: Sequence[str],
                 ratios: Sequence[float], path: Path) -> Optional[Path]:
    """PNG of the success rate (%) against the ratio, one line per method (``plot.line_chart``)."""
    from .plot import line_chart

    series = {}
    for m in methods:
        rows = sorted((s for s in per_ratio if s.method == m), key=lambda s: s.ratio)
        series[m] = ([s.ratio for s in rows], [100.0 * s.success_rate for s in rows])
    line_chart(series, path, title="Synthetic zoom pairs: success (error < 3 px) against ratio",
               xlabel="resolution ratio", ylabel="success rate (%)", ylim=(0.0, 100.0),
               xticks=[float(r) for r in ratios])
    return path


def write_csv(rows: Sequence[Dict[str, Any]], path: Path) -> Path:
    """One line per (method, pair)."""
    keys = ["method", "kind", "source", "high_source", "ratio", "angle_deg", "model", "claimed",
            "success", "error_px", "similarity_floor_px", "seconds", "inliers", "matches", "reason", "transform"]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{r[k]:.6g}" if isinstance(r[k], float) else r[k]) for k in keys})
    return path


# --------------------------------------------------------------------------------------------
# The run
# --------------------------------------------------------------------------------------------

def _quiet(_: str) -> None:
    pass


def run_benchmark(*, shared: Optional[PathLike] = None, out_dir: PathLike = "bench-out",
                  ratios: Sequence[float] = RATIOS, photos: Optional[int] = None, seed: int = 0,
                  methods: Sequence[str] = METHOD_NAMES, unrelated: int = UNRELATED_COUNT,
                  jobs: int = 2, batch_size: int = BATCH_SIZE, boat: bool = True,
                  large: bool = True, batch: bool = True, command: str = "",
                  log: Optional[Callable[[str], None]] = None, crop: str = "most") -> BenchReport:
    """Make the pairs, run every method on them, and write the CSV, the summary and the plot.

    Parameters
    ----------
    shared : path, optional
        The shared folder (``datasets.find_shared()`` when None).
    out_dir : path
        Where ``results.csv``, ``summary.json``, ``success_vs_ratio.png`` and the stored pairs
        (``pairs/``, deleted at the end) go.
    ratios : sequence of float
    photos : int, optional
        Use only the first ``photos`` photos (sorted by name); None uses all.
    seed : int
        The one seed: pairs, unrelated combinations, RANSAC of every method.
    methods : sequence of str
        Names from ALL_METHODS; a method whose code cannot be imported is skipped (logged and
        listed in ``BenchReport.skipped``).
    unrelated : int
        Number of unrelated pairs (false-match test).
    jobs : int
        The batch of ``batch_size`` pairs is timed with 1 and ``jobs`` worker processes.
    boat, large, batch : bool
        Include the boat pairs, the 6000x4000 pair, the batch timing.
    command : str
        The command line, recorded in the summary.
    log : callable, optional
        Receives progress lines (the CLI passes ``click.echo``); None is silent.

    Returns
    -------
    BenchReport
    """
    log = log or _quiet
    load_at_start = _load_average()
    shared_path = Path(shared) if shared is not None else find_shared()
    if shared_path is None or not (shared_path / "data" / "photos").is_dir():
        raise ValueError("the shared data folder was not found: pass shared=... or set "
                         "SCALEMATCH_SHARED to the folder holding data/photos")
    unknown = [m for m in methods if m not in ALL_METHODS]
    if unknown:
        raise ValueError(f"unknown method(s) {unknown}; choose from {', '.join(ALL_METHODS)}")
    ratios = tuple(float(r) for r in ratios)
    if not ratios or min(ratios) < 1:
        raise ValueError("ratios must be a non-empty list of values >= 1")
    paths = list_photos(shared_path)
    if photos is not None:
        paths = paths[:max(int(photos), 0)]
    if not paths:
        raise ValueError(f"no photos in {shared_path / 'data' / 'photos'}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    chosen: Dict[str, Method] = {}
    skipped: List[Tuple[str, str]] = []
    for name in methods:
        try:
            chosen[name] = make_method(name, seed)
        except ImportError as exc:
            skipped.append((name, f"cannot import: {exc}"))
            log(f"note: skipping {name}: cannot import its code ({exc})")
        except ValueError as exc:
            skipped.append((name, str(exc)))
            log(f"note: skipping {name}: {exc}")

    pair_dir = out / "pairs"
    records = prepare_pairs(paths, ratios, seed, pair_dir, shared_path, unrelated, boat, large, log,
                            crop)
    main_recs = [r for r in records if r.kind != "large"]
    large_recs = [r for r in records if r.kind == "large"]
    log(f"{len(main_recs)} pairs ({sum(r.kind == 'synthetic' for r in records)} synthetic, "
        f"{sum(r.kind == 'unrelated' for r in records)} unrelated, "
        f"{sum(r.kind == 'boat' for r in records)} boat) + {len(large_recs)} at 6000x4000")

    rows: List[Dict[str, Any]] = []
    memory: Dict[str, float] = {}
    large_res: Dict[str, Dict[str, float]] = {}
    batch_res: Dict[str, Tuple[Tuple[int, float], ...]] = {}
    batch_recs = [r for r in records if r.kind == "synthetic"][:batch_size]
    try:
        for name, method in chosen.items():
            t0 = time.perf_counter()
            models = {"similarity": method, BOAT_MODEL: make_method(name, seed, BOAT_MODEL)}
            got, mem = _in_fresh_process(_worker_run, models, main_recs)
            rows += [dict(r, method=name) for r in got]
            memory[name] = mem
            ok = sum(r["success"] for r in got if r["kind"] == "synthetic")
            n = sum(r["kind"] == "synthetic" for r in got)
            log(f"{name}: {ok}/{n} synthetic pairs matched, {mem:.0f} MB peak, "
                f"{time.perf_counter() - t0:.0f} s")
            for rec in large_recs:
                got_l, mem_l = _in_fresh_process(_worker_run, {"similarity": method}, [rec])
                rows += [dict(r, method=name) for r in got_l]
                large_res[name] = {"seconds": got_l[0]["seconds"], "memory_mb": mem_l,
                                   "error_px": got_l[0]["error_px"]}
                log(f"{name}: 6000x4000 pair in {got_l[0]['seconds']:.1f} s, {mem_l:.0f} MB")
            if batch and name in BATCH_METHODS and batch_recs:
                times = []
                for w in sorted({1, max(int(jobs), 1)}):
                    times.append((w, time_batch(method, batch_recs, w)))
                    log(f"{name}: batch of {len(batch_recs)} pairs with {w} worker(s): "
                        f"{times[-1][1]:.1f} s")
                batch_res[name] = tuple(times)
    finally:
        shutil.rmtree(pair_dir, ignore_errors=True)

    names = list(chosen)
    per_ratio, per_method = summarise(rows, names, ratios, memory, large_res, batch_res)
    table = format_tables(per_ratio, per_method, ratios, len(batch_recs)) + "\n" + \
        pair_by_pair(rows, names)
    if skipped:
        table += "\n" + "\n".join(f"Skipped {m}: {why}" for m, why in skipped) + "\n"
    csv_path = write_csv(rows, out / "results.csv")
    plot_path: Optional[Path] = None
    try:
        plot_path = plot_success(per_ratio, names, ratios, out / "success_vs_ratio.png")
    except ImportError as exc:
        log(f"note: no plot ({exc})")
    settings = {
        "command": command, "seed": seed, "ratios": list(ratios), "photos": [p.name for p in paths],
        "methods": names, "skipped": [list(s) for s in skipped], "unrelated": unrelated,
        "jobs": jobs, "batch_size": len(batch_recs), "success_px": SUCCESS_PX,
        "reference": REFERENCE, "machine": machine(),
        "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": _git_commit(), "opencv": cv2.__version__, "numpy": np.__version__,
        "python": platform.python_version(), "large_pair": large_recs[0].source if large_recs else "",
        "load_average_at_start": load_at_start, "opencv_threads": cv2.getNumThreads(),
        "crop": crop,
    }
    summary_path = out / "summary.json"
    with open(summary_path, "w") as f:
        json.dump(to_jsonable({"settings": settings, "per_ratio": [asdict(s) for s in per_ratio],
                             "per_method": [asdict(s) for s in per_method]}), f, indent=1)
    return BenchReport(per_ratio=per_ratio, per_method=per_method, rows=tuple(rows),
                       settings=settings, skipped=tuple(skipped), csv_path=csv_path,
                       plot_path=plot_path, summary_path=summary_path, table=table)


def _load_average() -> Optional[float]:
    """1-minute load average (other processes sharing the CPUs skew the times); None if unknown."""
    try:
        return round(os.getloadavg()[0], 2)
    except (OSError, AttributeError):
        return None


def machine() -> str:
    """CPU model and logical core count of this machine."""
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} logical cores, {platform.system()}"


def _git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, cwd=Path(__file__).resolve().parent,
                              timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def write_benchmarks_doc(report: BenchReport,
                         path: PathLike = "docs/results/BENCHMARKS.md") -> Path:
    """Write ``path`` (Markdown): the tables and plot of ``report``, the command, machine, date.

    The plot is copied next to it, named after the page (BENCHMARKS.md -> benchmarks.png, so
    several pages can live side by side). The page is generated: never edit a
    figure in it by hand, re-run the command.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    s = report.settings
    lines = ["# Benchmarks", "",
             "Generated by the benchmark command; do not edit by hand (re-run the command). "
             "Protocol: `EVALUATION.md` of the shared data folder: synthetic zoom pairs with "
             "exact ground truth cut from real photos, unrelated pairs, the Oxford boat "
             "sequence.", "",
             f"- Command: `{s['command']}`",
             f"- Date: {s['date']}; commit {s['commit'] or 'unknown'}",
             f"- Machine: {s['machine']}",
             f"- Software: Python {s['python']}, OpenCV {s['opencv']}, NumPy {s['numpy']}",
             f"- Seed {s['seed']}; ratios {', '.join(f'{r:g}' for r in s['ratios'])}; "
             f"{len(s['photos'])} photos; {s['unrelated']} unrelated pairs requested; the "
             f"high image is the {s.get('crop', 'most')} textured of 6 random crops "
             "(640x480, 960x720 beyond ratio 10)",
             f"- Reference for times: {s['reference']}. Each method runs alone in its own worker "
             "process; peak memory = the worker's peak resident set size minus its size before "
             "the first pair (after imports and a warm-up call).",
             f"- Load average when the run started: {s['load_average_at_start']} (times are "
             f"wall-clock; OpenCV, and scalematch with it, use {s['opencv_threads']} threads "
             "per call; in the batch of several workers, each uses one, as `scalematch batch` "
             "does).",
             ("- The 6000x4000 pair: " + s["large_pair"] + " (bicubic upscale of the largest "
              f"photo, centre cut), low image at ratio {LARGE_RATIO:g}.") if s["large_pair"]
             else "- The 6000x4000 pair was not run.",
             f"- A claim is any transform returned; the OpenCV baselines claim a match from "
             f"{MIN_INLIERS} RANSAC inliers up (`baselines.MIN_INLIERS`); the CSV's `inliers` "
             "column allows recounting false matches at another threshold.",
             f"- The boat pairs are judged against the homography truth, every method fitting "
             f"a {BOAT_MODEL} there (the best similarity is 0.3-1.0 px off on 1->2 .. 1->5 and "
             "3.9 px on 1->6: see `similarity_floor_px` in the CSV).", ""]
    if report.plot_path is not None and Path(report.plot_path).is_file():
        png = p.stem.lower() + ".png"
        shutil.copyfile(report.plot_path, p.parent / png)
        lines += [f"![success rate against ratio]({png})", ""]
    lines += [report.table, "", "Photos: " + ", ".join(f"`{n}`" for n in s["photos"]), ""]
    p.write_text("\n".join(lines) + _real_pairs_sections(p))
    return p


def _real_pairs_sections(page: Path) -> str:
    """The sections ``scalematch lab real-pairs`` wrote into ``page``, each with its markers and
    in the page's order: the real pairs, and the realistic pairs of ``--sets realistic`` (kept:
    another command's figures), or ""."""
    from .realpairs import SECTIONS, markers

    old = page.read_text() if page.is_file() else ""
    kept = []
    for section in SECTIONS:
        begin, end = markers(section)
        if begin in old and end in old.split(begin, 1)[1]:
            body = old.split(begin, 1)[1].split(end, 1)[0]
            kept.append((old.index(begin), begin + body + end + "\n"))
    return "".join("\n" + block for _, block in sorted(kept))


# --------------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------------

def _csv_floats(ctx, param, value):
    try:
        return tuple(float(v) for v in value.split(",") if v.strip())
    except ValueError:
        raise click.BadParameter("give numbers separated by commas, e.g. 2,3,4,6,8,10")


def _csv_methods(ctx, param, value):
    names = tuple(v.strip() for v in value.split(",") if v.strip())
    bad = [n for n in names if n not in ALL_METHODS]
    if bad:
        raise click.BadParameter(f"unknown {', '.join(bad)}; choose from {', '.join(ALL_METHODS)}")
    return names


def _command_line(ctx: click.Context) -> str:
    args = sys.argv[1:]
    # drop the group and command names the user typed (``lab bench`` or ``bench``): the command
    # path names them already
    names = ctx.command_path.split()[1:]
    while args and names and args[0] == names[0]:
        args, names = args[1:], names[1:]
    while args and args[0] == ctx.info_name:
        args = args[1:]
    return " ".join([ctx.command_path, shlex.join(args)]).strip()


@click.command("bench")
@click.option("--shared", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=None, help="Shared data folder (default $SCALEMATCH_SHARED or ../shared).")
@click.option("--out-dir", type=click.Path(file_okay=False, path_type=Path), default="bench-out",
              show_default=True, help="Where results.csv, summary.json and the plot go.")
@click.option("--crop", type=click.Choice(CROP_PICKS), default="most", show_default=True,
              help="Which of 6 random crops each pair's high image is: the most textured "
                   "(EVALUATION.md) or the least (the hard set, docs/results/HARDSET.md).")
@click.option("--ratios", default=",".join(map(str, RATIOS)), show_default=True,
              callback=_csv_floats,
              help="Zoom ratios of the synthetic pairs.")
@click.option("--photos", type=click.IntRange(min=1), default=None,
              help="Use only the first N photos (sorted by name). Default: all.")
@click.option("--seed", type=int, default=0, show_default=True, help="The one seed of the run.")
@click.option("--methods", default=",".join(METHOD_NAMES), show_default=True,
              callback=_csv_methods, help="Methods to run, comma-separated.")
@click.option("--unrelated", type=click.IntRange(min=0), default=UNRELATED_COUNT,
              show_default=True, help="Unrelated pairs for the false-match count.")
@click.option("--jobs", type=click.IntRange(min=1), default=2, show_default=True,
              help="The batch is timed with 1 and this many worker processes.")
@click.option("--batch-size", type=click.IntRange(min=0), default=BATCH_SIZE, show_default=True,
              help="Pairs in the batch timing (0: no batch timing).")
@click.option("--no-large", is_flag=True, help="Skip the 6000x4000 pair.")
@click.option("--no-boat", is_flag=True, help="Skip the boat pairs.")
@click.option("--write-doc", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write this Markdown page (e.g. docs/results/BENCHMARKS.md).")
@click.option("--silent", is_flag=True, help="No progress lines (the table is still printed).")
@click.pass_context
def bench_command(ctx, shared, out_dir, crop, ratios, photos, seed, methods, unrelated, jobs,
                  batch_size, no_large, no_boat, write_doc, silent):
    """Benchmark scalematch against OpenCV SIFT, ORB, AKAZE and BRISK on the same pairs.

    Cuts synthetic zoom pairs with exact ground truth from the shared photos, adds unrelated
    pairs and the boat sequence, runs every method in its own worker process, and prints and
    writes success rate, median error, median time (and its ratio to SIFT's), peak memory and
    false matches.

    Example: scalematch lab bench --photos 10 --methods sift,orb,akaze,brisk
    """
    log = (lambda s: None) if silent else (lambda s: click.echo(s, err=True))
    shared = require_shared(shared)
    try:
        report = run_benchmark(shared=shared, out_dir=out_dir, ratios=ratios, photos=photos,
                               seed=seed, methods=methods, unrelated=unrelated, jobs=jobs,
                               batch_size=batch_size, boat=not no_boat, large=not no_large,
                               batch=batch_size > 0, command=_command_line(ctx), log=log,
                               crop=crop)
    except ValueError as exc:
        raise click.ClickException(str(exc))
    click.echo(report.table)
    click.echo(f"per-pair results: {report.csv_path}")
    if report.plot_path is not None:
        click.echo(f"plot: {report.plot_path}")
    if write_doc is not None:
        click.echo(f"wrote {write_benchmarks_doc(report, write_doc)}")


def main(argv: Optional[Sequence[str]] = None) -> None:
    """Entry point of ``python -m scalematch.lab.bench``."""
    bench_command.main(args=None if argv is None else list(argv),
                       prog_name="python -m scalematch.lab.bench")


if __name__ == "__main__":
    # run through the package module, so that what the spawned workers unpickle
    # (methods, records) lives in ``scalematch.lab.bench``, not in ``__main__``
    from scalematch.lab.bench import main as _main

    _main()
