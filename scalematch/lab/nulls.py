"""The null set: pairs that have no answer, run in both orders, and what the evidence looks like.

A false claim (a transform reported on a pair that has none) is the worst outcome of a match.
This module builds pairs where any claim is false, runs ``scalematch.match`` on them, records
every scalar of ``MatchResult.evidence``, and charts its distribution against true pairs'.

Two kinds of null pair, cut from the photos of ``shared/data/photos`` (read at run time):

* ``unrelated``: the low image of photo A, made as EVALUATION.md makes a low image (blur, turn,
  shrink by the ratio, grey-level change, noise, a window of at most 1024x768), against a high
  crop (about 640x480, the most textured of 6) of a photo B of another scene (scene = the file
  name's prefix before the first ``_``; two photos of one scene may truly overlap);
* ``same-photo``, the hardest nulls: one photo cut in two halves across its longer side with a
  gap between them (``split_rects``); the low image is made from one half only (the half is cut
  out *before* the blur and warp, so no pixel of the other half reaches it) and the high crop is
  taken inside the other half. The texture is the same, the answer does not exist.

Every pair is made from ``pair_rng``-style generators keyed by the seed, the kind, the photo
names and the ratio, so a pair does not depend on the other pairs of the run. Each pair is run
in both orders: ``given`` = ``match(low, high)``, ``swapped`` = ``match(high, low)``.

Pair images are stored as PNG under ``<out-dir>/pairs-seed<seed>/`` with ``manifest.json`` (kind,
photos, ratio, seed, rectangles) and re-used when present; each run appends one JSON line to
``<out-dir>/nulls_<mode>_seed<seed>.jsonl`` (resumed: runs already there are skipped). Rectangles
are ``(x, y, w, h)`` in px of the photo, OpenCV convention.

Run ``scalematch lab nulls --help``.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import enum
import json
import math
import os
import platform
import shutil
import time
import zlib
from collections import Counter
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import click
import cv2
import numpy as np

from ..geometry import apply, compose, invert
from .datasets import find_shared, list_photos, require_shared, scene_of
from .synthetic import (HIGH_SIZE, LOW_MAX, _translation, choose_crop, make_zoom_pair,
                        pair_rng)

#: The two kinds of null pair (see the module docstring).
KINDS = ("unrelated", "same-photo")
#: Kind of the true pairs run by the same recorder (``--true N``) for the overlay.
TRUE_KIND = "true"
#: Zoom ratios of the null pairs: EVALUATION.md's 2-10, and 12 and 16, which the default's
#: scales reach.
RATIOS = (2, 3, 4, 6, 8, 10, 12, 16)
#: The two orders each pair is run in: ``given`` = match(low, high), ``swapped`` = match(high, low).
ORDERS = ("given", "swapped")
#: The evidence keys charted and summarised, in this order; a key absent from every row is left
#: out (names change as the decision grows: every scalar key is recorded whatever its name).
CHART_KEYS = ("log10_nfa", "inliers", "candidates", "agreeing_scales", "probe_best",
              "grown_inliers", "pixel_ncc", "pixel_margin", "unique_ratio", "scales_max_inliers",
              "footprint_ncc")
#: Charted keys read from the row itself when the evidence lacks them (the recorder's own
#: figures, e.g. the most inliers any scale of the reported search reached).
ROW_KEYS = ("scales_max_inliers", "footprint_ncc")
#: Gap between the two halves of a same-photo pair, as a fraction of the split side, and at
#: least ``SPLIT_GAP_MIN_PX``: the two regions are disjoint with a margin, so no feature (a
#: Harris window, a descriptor patch, the blur) can see across.
SPLIT_GAP_FRAC = 0.04
SPLIT_GAP_MIN_PX = 32
#: Photos kept decoded while the pairs are made (each is 30-80 MB as float32).
PHOTO_CACHE = 4
#: Percentiles reported for each charted key.
PERCENTILES = (5, 25, 50, 75, 95)
#: The default output folder (git-ignored).
DEFAULT_OUT = Path("bench-out") / "nulls"

PathLike = Union[str, Path]
Rect = Tuple[int, int, int, int]


# --------------------------------------------------------------------------------------------
# Pair specifications and construction (pure numpy)
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class NullSpec:
    """What defines one pair before any pixel is made."""

    kind: str  #: unrelated | same-photo | true
    photo: str  #: file name of the photo the low image is made from
    high_photo: str  #: file name of the photo the high crop is cut from
    ratio: float  #: zoom ratio of the low image (high px per low px)
    seed: int  #: the run's seed

    @property
    def pair_id(self) -> str:
        """A readable id, unique in a run: ``kind:photo[>high_photo]:xR``."""
        other = "" if self.high_photo == self.photo else ">" + self.high_photo
        return f"{self.kind}:{self.photo}{other}:x{self.ratio:g}"

    @property
    def file_stem(self) -> str:
        """The stem of the pair's PNG files (``<stem>_low.png``, ``<stem>_high.png``)."""
        crc = zlib.crc32(self.pair_id.encode("utf-8"))
        return f"{self.kind}_{Path(self.photo).stem[:40]}_x{self.ratio:g}_{crc:08x}"

    def rng(self) -> np.random.Generator:
        """The pair's generator: from the seed, kind, photo names and ratio only."""
        return pair_rng(self.seed, f"{self.kind}|{self.photo}|{self.high_photo}", self.ratio)


@dataclass(frozen=True, eq=False)
class NullPair:
    """A made pair: images and where each comes from.

    ``low_region`` is the part of ``photo`` the low image shows (the bounding box of the low
    window's preimage, inside the half for a same-photo pair); ``high_rect`` the crop of
    ``high_photo`` that is the high image. For a same-photo pair the two are disjoint.
    """

    spec: NullSpec
    low: np.ndarray = field(repr=False)  #: (H, W) uint8
    high: np.ndarray = field(repr=False)  #: (h, w) uint8
    low_region: Rect  #: in ``photo`` px
    high_rect: Rect  #: in ``high_photo`` px
    angle_deg: float  #: rotation of the low image
    split: str = ""  #: same-photo: "left|right" etc. (low half first); "" otherwise
    truth: Optional[np.ndarray] = field(default=None, repr=False)  #: true pairs: high px -> low px


def split_rects(shape: Tuple[int, int], low_first: bool, gap_frac: float = SPLIT_GAP_FRAC,
                min_gap_px: int = SPLIT_GAP_MIN_PX) -> Tuple[Rect, Rect, str]:
    """Two disjoint halves of a photo of ``shape`` (H, W), cut across its longer side.

    Returns (low half, high half, name), each half ``(x, y, w, h)``, separated by a gap of
    ``max(gap_frac * side, min_gap_px)`` px; ``low_first`` puts the low half on the left (or
    top). ``name`` says which is which, e.g. "left|right" (low half | high half).
    """
    h, w = int(shape[0]), int(shape[1])
    side = max(w, h)
    gap = max(int(round(gap_frac * side)), int(min_gap_px))
    half = (side - gap) // 2
    if half < 64:
        raise ValueError(f"a {w}x{h} photo is too small to split in two halves")
    if w >= h:
        a, b, names = (0, 0, half, h), (w - half, 0, half, h), ("left", "right")
    else:
        a, b, names = (0, 0, w, half), (0, h - half, w, half), ("top", "bottom")
    if low_first:
        return a, b, f"{names[0]}|{names[1]}"
    return b, a, f"{names[1]}|{names[0]}"


def rects_overlap(a: Rect, b: Rect) -> bool:
    """True when the rectangles ``(x, y, w, h)`` share at least one pixel."""
    return (a[0] < b[0] + b[2] and b[0] < a[0] + a[2]
            and a[1] < b[1] + b[3] and b[1] < a[1] + a[3])


def _preimage_box(photo_to_low: np.ndarray, low_shape: Tuple[int, int], bounds: Rect) -> Rect:
    """Bounding box, clipped to ``bounds``, of the photo pixels that map inside the low image."""
    lh, lw = low_shape[:2]
    corners = np.array([[-0.5, -0.5], [lw - 0.5, -0.5], [lw - 0.5, lh - 0.5], [-0.5, lh - 0.5]])
    pts = apply(invert(photo_to_low), corners)
    bx, by, bw, bh = bounds
    x0 = max(int(math.floor(pts[:, 0].min())), bx)
    y0 = max(int(math.floor(pts[:, 1].min())), by)
    x1 = min(int(math.ceil(pts[:, 0].max())) + 1, bx + bw)
    y1 = min(int(math.ceil(pts[:, 1].max())) + 1, by + bh)
    return x0, y0, max(x1 - x0, 0), max(y1 - y0, 0)


def _u8(image: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def make_same_photo_null(photo: np.ndarray, spec: NullSpec,
                         high_size: Tuple[int, int] = HIGH_SIZE,
                         low_max: Tuple[int, int] = LOW_MAX) -> NullPair:
    """The hardest null: low image from one half of ``photo``, high crop from the other half.

    ``spec.rng()`` draws, in order: which half is the low one, then everything
    ``synthetic.make_zoom_pair`` draws on the low half (crop positions, angle, gain, offset,
    noise std, window, noise), then the high crop's positions (``choose_crop``, the most
    textured of 6 inside the other half).
    """
    photo = np.asarray(photo, np.float32)
    rng = spec.rng()
    low_rect, high_half, split = split_rects(photo.shape, bool(rng.integers(0, 2)))
    lx, ly, lw, lh = low_rect
    half = np.ascontiguousarray(photo[ly:ly + lh, lx:lx + lw])
    zp = make_zoom_pair(half, spec.ratio, rng, high_size, low_max, source=spec.photo)
    # photo px -> low px: the zoom pair's truth maps its (phantom) crop px to low px
    photo_to_low = compose(zp.truth, _translation(-zp.crop_xy[0] - lx, -zp.crop_xy[1] - ly))
    low_region = _preimage_box(photo_to_low, zp.low.shape, low_rect)
    hx, hy, hw, hh = high_half
    cx, cy, cw, ch = choose_crop(photo[hy:hy + hh, hx:hx + hw], spec.ratio, rng, high_size)
    high_rect = (hx + cx, hy + cy, cw, ch)
    high = photo[high_rect[1]:high_rect[1] + ch, high_rect[0]:high_rect[0] + cw]
    return NullPair(spec=spec, low=_u8(zp.low), high=_u8(high), low_region=low_region,
                    high_rect=high_rect, angle_deg=zp.angle_deg, split=split)


def make_unrelated_null(photo_low: np.ndarray, photo_high: np.ndarray, spec: NullSpec,
                        high_size: Tuple[int, int] = HIGH_SIZE,
                        low_max: Tuple[int, int] = LOW_MAX) -> NullPair:
    """The low image of ``photo_low`` against a high crop of ``photo_high`` (another scene).

    As ``synthetic.make_unrelated_pair`` (the same draws in the same order from
    ``spec.rng()``), keeping the rectangles for the manifest.
    """
    photo_low = np.asarray(photo_low, np.float32)
    photo_high = np.asarray(photo_high, np.float32)
    rng = spec.rng()
    zp = make_zoom_pair(photo_low, spec.ratio, rng, high_size, low_max, source=spec.photo)
    photo_to_low = compose(zp.truth, _translation(-zp.crop_xy[0], -zp.crop_xy[1]))
    ph, pw = photo_low.shape
    low_region = _preimage_box(photo_to_low, zp.low.shape, (0, 0, pw, ph))
    x, y, w, h = choose_crop(photo_high, spec.ratio, rng, high_size)
    return NullPair(spec=spec, low=_u8(zp.low), high=_u8(photo_high[y:y + h, x:x + w]),
                    low_region=low_region, high_rect=(x, y, w, h), angle_deg=zp.angle_deg)


def make_true_pair(photo: np.ndarray, spec: NullSpec,
                   high_size: Tuple[int, int] = HIGH_SIZE,
                   low_max: Tuple[int, int] = LOW_MAX) -> NullPair:
    """A zoom pair with its truth, exactly as ``synthetic.pairs_from_photos`` makes it
    (generator ``pair_rng(seed, photo name, ratio)``), for the true-pair overlay."""
    zp = make_zoom_pair(photo, spec.ratio, pair_rng(spec.seed, spec.photo, spec.ratio),
                        high_size, low_max, source=spec.photo)
    x, y = zp.crop_xy
    photo_to_low = compose(zp.truth, _translation(-x, -y))
    ph, pw = np.shape(photo)[:2]
    return NullPair(spec=spec, low=_u8(zp.low), high=_u8(zp.high),
                    low_region=_preimage_box(photo_to_low, zp.low.shape, (0, 0, pw, ph)),
                    high_rect=(x, y, zp.high.shape[1], zp.high.shape[0]),
                    angle_deg=zp.angle_deg, truth=zp.truth)


def null_specs(photos: Sequence[str], ratios: Sequence[float] = RATIOS, seed: int = 0,
               kinds: Sequence[str] = KINDS,
               scene: Callable[[str], str] = scene_of) -> List[NullSpec]:
    """One spec per photo, ratio and kind, in a fixed run order.

    The partner B of an unrelated pair is drawn (from the seed, photo and ratio only) among the
    photos of other scenes; a photo with no such partner gets no unrelated pair. The order: each
    kind shuffled by the seed, then the kinds interleaved, so that any prefix of the list (a
    ``--limit``, a run cut short) is a balanced sample of kinds, photos and ratios.
    """
    names = sorted(str(p) for p in photos)
    per_kind: Dict[str, List[NullSpec]] = {k: [] for k in kinds}
    for name in names:
        others = [o for o in names if scene(o) != scene(name)]
        for r in ratios:
            r = float(r)
            if "same-photo" in per_kind:
                per_kind["same-photo"].append(NullSpec("same-photo", name, name, r, int(seed)))
            if "unrelated" in per_kind and others:
                pick = pair_rng(seed, "partner|" + name, r).integers(0, len(others))
                per_kind["unrelated"].append(
                    NullSpec("unrelated", name, others[int(pick)], r, int(seed)))
    shuffled = []
    for k, kind in enumerate(kinds):
        items = per_kind[kind]
        order = np.random.default_rng([int(seed), 7, k]).permutation(len(items))
        shuffled.append([items[i] for i in order])
    out: List[NullSpec] = []
    for i in range(max((len(s) for s in shuffled), default=0)):
        out += [s[i] for s in shuffled if i < len(s)]
    return out


def true_specs(photos: Sequence[str], count: int, ratios: Sequence[float] = RATIOS,
               seed: int = 0) -> List[NullSpec]:
    """``count`` true zoom pairs: (photo, ratio) combinations in a seeded order, ratios cycled
    so that any prefix spreads over them."""
    names = sorted(str(p) for p in photos)
    rng = np.random.default_rng([int(seed), 11])
    per_ratio = [[names[i] for i in rng.permutation(len(names))] for _ in ratios]
    out = []
    for i in range(len(names)):
        for r, col in zip(ratios, per_ratio):
            out.append(NullSpec(TRUE_KIND, col[i], col[i], float(r), int(seed)))
    return out[:max(int(count), 0)]


def make_pair(spec: NullSpec, load: Callable[[str], np.ndarray]) -> NullPair:
    """Make the pair of ``spec``; ``load(name)`` returns a photo as (H, W) float32 grey."""
    if spec.kind == "same-photo":
        return make_same_photo_null(load(spec.photo), spec)
    if spec.kind == "unrelated":
        return make_unrelated_null(load(spec.photo), load(spec.high_photo), spec)
    if spec.kind == TRUE_KIND:
        return make_true_pair(load(spec.photo), spec)
    raise ValueError(f"unknown pair kind {spec.kind!r}; one of {KINDS + (TRUE_KIND,)}")


# --------------------------------------------------------------------------------------------
# The pair store: PNG files and a manifest, re-used when present
# --------------------------------------------------------------------------------------------

def _manifest_entry(pair: NullPair, low_file: str, high_file: str) -> Dict[str, Any]:
    s = pair.spec
    return {"pair_id": s.pair_id, "kind": s.kind, "photo": s.photo, "high_photo": s.high_photo,
            "ratio": s.ratio, "seed": s.seed, "angle_deg": round(pair.angle_deg, 4),
            "low_file": low_file, "high_file": high_file,
            "low_shape": list(pair.low.shape), "high_shape": list(pair.high.shape),
            "low_region": list(pair.low_region), "high_rect": list(pair.high_rect),
            "split": pair.split,
            "truth": None if pair.truth is None else np.asarray(pair.truth).tolist()}


def read_manifest(folder: Path) -> Dict[str, Dict[str, Any]]:
    """pair_id -> manifest entry of the pairs stored in ``folder`` (empty when none)."""
    path = Path(folder) / "manifest.json"
    if not path.is_file():
        return {}
    with open(path) as f:
        return {e["pair_id"]: e for e in json.load(f)}


def _write_manifest(folder: Path, entries: Dict[str, Dict[str, Any]]) -> None:
    tmp = folder / "manifest.json.tmp"
    with open(tmp, "w") as f:
        json.dump(sorted(entries.values(), key=lambda e: e["pair_id"]), f, indent=1)
    os.replace(tmp, folder / "manifest.json")


def ensure_pairs(specs: Sequence[NullSpec], folder: PathLike, photo_dir: PathLike,
                 log: Callable[[str], None] = lambda s: None) -> Dict[str, Dict[str, Any]]:
    """Make and store every pair of ``specs`` not already in ``folder``; pair_id -> entry.

    Photos are read from ``photo_dir`` (``imageio.read_grey``), a few kept decoded at a time;
    pairs are made photo by photo. A stored pair is re-used when its entry and both PNGs exist.
    """
    from ..imageio import read_grey

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    entries = read_manifest(folder)
    todo = [s for s in specs if not (
        s.pair_id in entries and (folder / entries[s.pair_id]["low_file"]).is_file()
        and (folder / entries[s.pair_id]["high_file"]).is_file())]
    cache: Dict[str, np.ndarray] = {}

    def load(name: str) -> np.ndarray:
        if name not in cache:
            if len(cache) >= PHOTO_CACHE:
                cache.pop(next(iter(cache)))
            cache[name] = read_grey(Path(photo_dir) / name)
        return cache[name]

    t0 = time.perf_counter()
    for k, spec in enumerate(sorted(todo, key=lambda s: (s.photo, s.high_photo, s.ratio))):
        pair = make_pair(spec, load)
        low_file, high_file = spec.file_stem + "_low.png", spec.file_stem + "_high.png"
        cv2.imwrite(str(folder / low_file), pair.low)
        cv2.imwrite(str(folder / high_file), pair.high)
        entries[spec.pair_id] = _manifest_entry(pair, low_file, high_file)
        if (k + 1) % 25 == 0 or k + 1 == len(todo):
            _write_manifest(folder, entries)
            log(f"made {k + 1}/{len(todo)} pairs ({time.perf_counter() - t0:.0f} s)")
    if not todo and not (folder / "manifest.json").is_file():
        _write_manifest(folder, entries)
    return {s.pair_id: entries[s.pair_id] for s in specs}


# --------------------------------------------------------------------------------------------
# The recorder: one run = one pair in one order
# --------------------------------------------------------------------------------------------

def run_id(pair_id: str, order: str, mode: str) -> str:
    """The key a row is resumed by."""
    return f"{pair_id}|{order}|{mode}"


def make_tasks(entries: Iterable[Dict[str, Any]], folder: PathLike, mode: str = "default",
               sift: bool = False, seed: int = 0) -> List[Dict[str, Any]]:
    """Both orders of each pair, in the order given: one task (a plain dict) per run.

    With ``sift``, the reference runs on the same images in the same order right before or
    after scalematch: scalematch first on even runs, SIFT first on odd ones (alternation).
    """
    tasks = []
    for e in entries:
        for order in ORDERS:
            k = len(tasks)
            tasks.append({"run_id": run_id(e["pair_id"], order, mode), "pair_id": e["pair_id"],
                          "kind": e["kind"], "order": order, "mode": mode, "seed": seed,
                          "ratio": e["ratio"], "photo": e["photo"],
                          "high_photo": e["high_photo"],
                          "low_file": str(Path(folder) / e["low_file"]),
                          "high_file": str(Path(folder) / e["high_file"]),
                          "truth": e.get("truth"), "sift": bool(sift),
                          "first": "sift" if (sift and k % 2) else "scalematch"})
    return tasks


def scalar_evidence(evidence: Any) -> Dict[str, Any]:
    """Every scalar (number, bool, string) of an evidence dict or dataclass (``result.Evidence``),
    as plain JSON values.

    >>> scalar_evidence({"inliers": np.float64(5), "log10_nfa": float("inf"), "xy": [1, 2]})
    {'inliers': 5.0, 'log10_nfa': 'inf'}
    """
    if dataclasses.is_dataclass(evidence):
        evidence = dataclasses.asdict(evidence)
    out: Dict[str, Any] = {}
    for k, v in dict(evidence or {}).items():
        if isinstance(v, enum.Enum):
            v = v.value
        if isinstance(v, (bool, np.bool_)):
            out[str(k)] = bool(v)
        elif isinstance(v, (int, float, np.integer, np.floating)):
            f = float(v)  # JSON has no inf/nan: those are kept as the strings "inf", "nan"
            out[str(k)] = f if math.isfinite(f) else str(f)
        elif isinstance(v, str):
            out[str(k)] = v
    return out


#: The configurations a null set is run in (``Config.preset`` names)
NULL_MODES = ("default", "paper", "tilt-4", "budget-1s", "affine", "homography",
              "homography-searched", "fundamental", "no-views")


def _config(mode: str, seed: int):
    from ..config import Config

    return Config.preset(mode, seed=seed)


def _read(path: str) -> np.ndarray:
    img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise FileNotFoundError(f"cannot read the stored pair image {path}")
    return img.astype(np.float32)


def run_task(task: Dict[str, Any]) -> Dict[str, Any]:
    """Run one task (``make_tasks``): scalematch, and SIFT when asked; one JSON row."""
    from ..pipeline import match
    from .baselines import match_baseline
    from .bench import _peak_mb, _reset_peak, _rss_mb
    from .evaluation import is_success, reprojection_error

    low, high = _read(task["low_file"]), _read(task["high_file"])
    a, b = (low, high) if task["order"] == "given" else (high, low)
    config = _config(task["mode"], task["seed"])
    row: Dict[str, Any] = {k: task[k] for k in ("run_id", "pair_id", "kind", "order", "mode",
                                                "ratio", "photo", "high_photo")}

    def run_scalematch() -> None:
        base = _rss_mb()
        reset = _reset_peak()
        t0 = time.perf_counter()
        try:
            r = match(a, b, config)
        except Exception as exc:  # noqa: BLE001 - a crash is recorded, not a false claim
            row.update(matched=False, reason=f"error: {type(exc).__name__}: {exc}",
                       seconds=time.perf_counter() - t0, evidence={})
            return
        row["seconds"] = time.perf_counter() - t0
        row["peak_mb"] = round(max(_peak_mb() - base, 0.0), 1) if reset else None
        row.update(matched=bool(r.matched), reason=r.reason, result_order=r.order,
                   model=r.model, best_scale=_finite(r.best_scale), inliers=r.n_inliers,
                   resolution_ratio=_finite(r.resolution_ratio),
                   rotation_deg=_finite(r.rotation_deg),
                   transform=None if r.transform is None else np.round(
                       np.asarray(r.transform, float), 6).tolist(),
                   scales_max_inliers=max((s.inliers for s in r.scales), default=0),
                   scales_max_kept=max((s.kept for s in r.scales), default=0),
                   evidence=scalar_evidence(r.evidence))

    def run_sift() -> None:
        t0 = time.perf_counter()
        s = match_baseline(a, b, "sift", seed=task["seed"])
        row["sift"] = {"seconds": time.perf_counter() - t0, "claimed": s.transform is not None,
                       "inliers": s.inliers, "matches": s.matches}

    steps = [run_scalematch] + ([run_sift] if task.get("sift") else [])
    for fn in (steps[::-1] if task.get("first") == "sift" else steps):
        fn()
    row["first"] = task.get("first", "scalematch")
    if task.get("truth") is None:  # a null pair: any claim is false
        row["false_claim"] = bool(row["matched"])
        if "sift" in row:
            row["sift"]["false_claim"] = bool(row["sift"]["claimed"])
    else:  # a true pair: the transform, whatever the order found, maps high px to low px
        truth = np.asarray(task["truth"], float)
        t = row.get("transform")
        err = reprojection_error(None if t is None else np.asarray(t), truth,
                                 high.shape, low.shape)
        row["error_px"] = _finite(err)
        row["success"] = bool(row["matched"] and is_success(err))
        row["false_claim"] = bool(row["matched"] and not is_success(err))
    return row


def footprint_ncc(low: np.ndarray, high: np.ndarray, transform: np.ndarray) -> float:
    """Normalised cross-correlation of ``low`` with ``high`` placed by ``transform`` on it.

    ``high`` is blurred for the shrink (``CAMERA_BLUR_PX * sqrt(r^2 - 1)``, the camera model of
    the synthetic pairs), warped by ``transform`` (2x3, high px -> low px) and compared with
    the low pixels it covers: 1 for the same content, about 0 for unrelated content. A figure
    of the recorder (the lab's view of a claim), not the pipeline's evidence; nan when the
    footprint covers fewer than 16 low pixels.
    """
    from .synthetic import CAMERA_BLUR_PX

    t = np.asarray(transform, np.float64)[:2]
    r = 1.0 / max(math.sqrt(abs(np.linalg.det(t[:, :2]))), 1e-9)
    hi = np.asarray(high, np.float32)
    blur = CAMERA_BLUR_PX * math.sqrt(max(r * r - 1.0, 0.0))
    if blur > 0.05:
        hi = cv2.GaussianBlur(hi, (0, 0), blur)
    size = (int(low.shape[1]), int(low.shape[0]))
    warped = cv2.warpAffine(hi, t, size, flags=cv2.INTER_LINEAR)
    mask = cv2.warpAffine(np.ones(hi.shape, np.uint8), t, size, flags=cv2.INTER_NEAREST) > 0
    if mask.sum() < 16:
        return math.nan
    a = np.asarray(low, np.float64)[mask]
    b = warped[mask].astype(np.float64)
    a, b = a - a.mean(), b - b.mean()
    den = math.sqrt(float((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / den) if den > 0 else math.nan


def _maps_points(row: Dict[str, Any]) -> bool:
    """Whether a row's transform maps a point to a point (has a footprint): not a fundamental
    matrix, which maps a point to a line."""
    from ..stages.decision import maps_points

    return maps_points(row.get("model") or "similarity")


def add_footprint_ncc(rows: Sequence[Dict[str, Any]], entries: Dict[str, Dict[str, Any]],
                      folder: PathLike) -> None:
    """Set ``footprint_ncc`` on every matched row lacking it (in place; from the stored PNGs).

    The transform maps the finer image to the coarser one: the pair's high to its low when
    the match kept the pair's order (run ``given`` found ``given``, or ``swapped`` found
    ``swapped``), else the other way round.
    """
    for r in rows:
        if not r.get("matched") or r.get("transform") is None or "footprint_ncc" in r \
                or not _maps_points(r):
            continue
        e = entries.get(r.get("pair_id"))
        if e is None:
            continue
        low = _read(str(Path(folder) / e["low_file"]))
        high = _read(str(Path(folder) / e["high_file"]))
        if (r.get("order") == "given") != (r.get("result_order", "given") == "given"):
            low, high = high, low
        r["footprint_ncc"] = _finite(footprint_ncc(low, high, np.asarray(r["transform"])))


def false_claim_figure(rows: Sequence[Dict[str, Any]], entries: Dict[str, Dict[str, Any]],
                       folder: PathLike, path: PathLike, tile: int = 180,
                       per_row: int = 3) -> Optional[np.ndarray]:
    """A picture of each false claim (one per pair): the low image's pixels under the claimed
    footprint (left) beside the high image placed there by the claim (right), captioned with
    the pair id, inliers, log10 NFA and footprint NCC. BGR; None (nothing written) when there
    is no false claim."""
    seen, tiles = set(), []
    for r in rows:
        if not r.get("false_claim") or r.get("pair_id") in seen or r.get("transform") is None \
                or not _maps_points(r):
            continue
        e = entries.get(r["pair_id"])
        if e is None:
            continue
        seen.add(r["pair_id"])
        low = cv2.imread(str(Path(folder) / e["low_file"]), cv2.IMREAD_GRAYSCALE)
        high = cv2.imread(str(Path(folder) / e["high_file"]), cv2.IMREAD_GRAYSCALE)
        if (r.get("order") == "given") != (r.get("result_order", "given") == "given"):
            low, high = high, low
        t = np.asarray(r["transform"], np.float64)[:2]
        size = (low.shape[1], low.shape[0])
        placed = cv2.warpAffine(high, t, size, flags=cv2.INTER_AREA)
        mask = cv2.warpAffine(np.ones_like(high), t, size, flags=cv2.INTER_NEAREST) > 0
        if not mask.any():
            continue
        ys, xs = np.nonzero(mask)
        box = (slice(ys.min(), ys.max() + 1), slice(xs.min(), xs.max() + 1))
        pair = [cv2.resize(img[box], (tile, tile), interpolation=cv2.INTER_AREA)
                for img in (low, placed)]
        cell = np.full((tile + 44, 2 * tile + 6), 255, np.uint8)
        cell[44:, :tile], cell[44:, tile + 6:] = pair
        ev = r.get("evidence") or {}
        lines = (f"{r['pair_id'][:48]}",
                 f"{r.get('inliers')} inliers, log10 NFA {_fmt(ev.get('log10_nfa'), '.1f')}, "
                 f"NCC {_fmt(r.get('footprint_ncc'))}")
        for k, text in enumerate(lines):
            cv2.putText(cell, text, (4, 17 + 20 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.45, 0, 1,
                        cv2.LINE_AA)
        tiles.append(np.pad(cell, ((0, 10), (0, 16)), constant_values=255))
    if not tiles:
        return None
    while len(tiles) % per_row:
        tiles.append(np.full_like(tiles[0], 255))
    img = np.vstack([np.hstack(tiles[i:i + per_row]) for i in range(0, len(tiles), per_row)])
    cv2.imwrite(str(path), img)  # grey: a third of the file a BGR one would take
    return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)


def _finite(v: Any) -> Optional[float]:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _worker_init(threads: int) -> None:
    if threads:
        cv2.setNumThreads(threads)


def load_rows(path: PathLike) -> List[Dict[str, Any]]:
    """The rows of a JSONL file; a last line cut by an interruption is dropped (and cut off
    the file, so that appending continues on a clean line)."""
    p = Path(path)
    if not p.is_file():
        return []
    data = p.read_bytes()
    if data and not data.endswith(b"\n"):
        data = data[:data.rfind(b"\n") + 1]
        with open(p, "wb") as f:
            f.write(data)
    rows = []
    for line in data.decode("utf-8").splitlines():
        if line.strip():
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    return rows


def made_on(run_commits: Dict[str, int]) -> str:
    """Which code made the rows: "rows made on 3dd204b (1216 runs)", "" for rows that
    predate the record.

    >>> made_on({"3dd204b": 1200, "": 16})
    'rows made on 3dd204b (1200 runs), on a commit not recorded (16 runs)'
    """
    parts = [f"{c or 'a commit not recorded'} ({n} runs)"
             for c, n in sorted(run_commits.items(), key=lambda kv: -kv[1])]
    return ("rows made on " + ", on ".join(parts)) if parts else "rows: none"


def execute(tasks: Sequence[Dict[str, Any]], rows_path: PathLike, jobs: int = 1,
            run: Callable[[Dict[str, Any]], Dict[str, Any]] = run_task,
            deadline: Optional[float] = None,
            log: Callable[[str], None] = lambda s: None) -> List[Dict[str, Any]]:
    """Run the tasks not yet in ``rows_path``, appending one JSON line per run; all rows.

    ``jobs`` 1 runs in this process (OpenCV's default threads); more use that many spawned
    worker processes with one OpenCV thread each (as ``scalematch batch`` and the benchmark
    do). ``deadline`` (a ``time.monotonic()`` value) stops starting new runs after it.
    """
    rows_path = Path(rows_path)
    rows_path.parent.mkdir(parents=True, exist_ok=True)
    done = load_rows(rows_path)
    done_ids = {r.get("run_id") for r in done}
    todo = [t for t in tasks if t["run_id"] not in done_ids]
    if len(todo) < len(tasks):
        log(f"resuming: {len(tasks) - len(todo)} of {len(tasks)} runs already in {rows_path}")
    new: List[Dict[str, Any]] = []
    t0 = time.perf_counter()
    from .bench import _git_commit

    commit = _git_commit()  # the code these runs are made with (a page may be written later)

    def record(row: Dict[str, Any]) -> None:
        row = dict(row, commit=commit)
        with open(rows_path, "a") as f:
            f.write(json.dumps(row, allow_nan=False, default=str) + "\n")
        new.append(row)
        n = len(new)
        if row.get("false_claim"):
            log(f"FALSE CLAIM: {row['run_id']}: {row.get('transform')} {row.get('evidence')}")
        if n % 10 == 0 or n == len(todo):
            log(f"{n}/{len(todo)} runs ({time.perf_counter() - t0:.0f} s, "
                f"{sum(bool(r.get('false_claim')) for r in new)} false claims)")

    def time_left() -> bool:
        return deadline is None or time.monotonic() < deadline

    if jobs <= 1:
        for task in todo:
            if not time_left():
                log("time budget spent: stopping (run again to resume)")
                break
            record(run(task))
        return done + new
    import multiprocessing as mp

    pending = list(todo)[::-1]
    with ProcessPoolExecutor(max_workers=jobs, mp_context=mp.get_context("spawn"),
                             initializer=_worker_init, initargs=(1,)) as ex:
        running = set()
        while pending or running:
            while pending and len(running) < 2 * jobs and time_left():
                running.add(ex.submit(run, pending.pop()))
            if not time_left() and pending:
                log("time budget spent: finishing the runs under way (run again to resume)")
                pending = []
            finished, running = wait(running, return_when=FIRST_COMPLETED)
            for fut in finished:
                record(fut.result())
    return done + new


# --------------------------------------------------------------------------------------------
# Summary, percentiles and the chart
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class GroupSummary:
    """The runs of one kind in one order (or "all")."""

    kind: str
    order: str
    runs: int
    false_claims: int
    median_seconds: float
    max_seconds: float
    sift_runs: int = 0
    sift_median_seconds: float = math.nan
    sift_claims: int = 0
    errors: int = 0  #: runs whose match raised


def _median(values: Sequence[Optional[float]]) -> float:
    v = [float(x) for x in values if x is not None and math.isfinite(float(x))]
    return float(np.median(v)) if v else math.nan


def _max(values: Sequence[Optional[float]]) -> float:
    v = [float(x) for x in values if x is not None and math.isfinite(float(x))]
    return float(max(v)) if v else math.nan


def summarise(rows: Sequence[Dict[str, Any]]) -> Tuple[GroupSummary, ...]:
    """Per (kind, order) summaries, each kind's "all", then the nulls' overall "all"/"all".

    A false claim is a row whose ``false_claim`` is true (nulls: any match; true pairs: a match
    more than 3 px off). SIFT's claims are counted on the rows that ran it.
    """
    def group(kind: str, order: str, rs: Sequence[Dict[str, Any]]) -> GroupSummary:
        sift = [r["sift"] for r in rs if isinstance(r.get("sift"), dict)]
        return GroupSummary(
            kind=kind, order=order, runs=len(rs),
            false_claims=sum(bool(r.get("false_claim")) for r in rs),
            median_seconds=_median([r.get("seconds") for r in rs]),
            max_seconds=_max([r.get("seconds") for r in rs]),
            sift_runs=len(sift), sift_median_seconds=_median([s.get("seconds") for s in sift]),
            sift_claims=sum(bool(s.get("claimed")) for s in sift),
            errors=sum(str(r.get("reason", "")).startswith("error:") for r in rs))

    kinds = [k for k in KINDS + (TRUE_KIND,) if any(r.get("kind") == k for r in rows)]
    out = []
    for kind in kinds:
        of_kind = [r for r in rows if r.get("kind") == kind]
        for order in ORDERS:
            out.append(group(kind, order, [r for r in of_kind if r.get("order") == order]))
        out.append(group(kind, "all", of_kind))
    nulls = [r for r in rows if r.get("kind") in KINDS]
    if nulls:
        out.append(group("all nulls", "all", nulls))
    return tuple(out)


def evidence_values(rows: Sequence[Dict[str, Any]], key: str) -> np.ndarray:
    """(N,) float64: the finite values of evidence ``key`` over ``rows`` (absent ones skipped)."""
    vals = []
    for r in rows:
        v = (r.get("evidence") or {}).get(key)
        if v is None and key in ROW_KEYS:
            v = r.get(key)
        if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
            vals.append(float(v))
    return np.asarray(vals, dtype=np.float64)


def chart_keys(rows: Sequence[Dict[str, Any]], keys: Sequence[str] = CHART_KEYS) -> List[str]:
    """The keys of ``keys`` with at least one finite value in ``rows``."""
    return [k for k in keys if evidence_values(rows, k).size]


def percentiles(rows: Sequence[Dict[str, Any]], keys: Sequence[str]) -> Dict[str, Dict[str, Any]]:
    """key -> {"n", "not_finite", "min", "p5", ..., "p95", "max"} over ``rows``.

    ``n`` counts the runs with a finite value of the key, ``not_finite`` those where it was
    inf or nan (recorded as strings, e.g. a log10 NFA with no more inliers than the sample;
    None in rows of earlier versions).
    """
    out = {}
    for k in keys:
        v = evidence_values(rows, k)
        ev = [r.get("evidence") or {} for r in rows]  # None: non-finite by an older recorder
        odd = sum(k in e and (e[k] is None or isinstance(e[k], str)) for e in ev)
        stats: Dict[str, Any] = {"n": int(v.size), "not_finite": int(odd)}
        if v.size:
            stats["min"] = float(v.min())
            stats.update({f"p{p}": float(np.percentile(v, p)) for p in PERCENTILES})
            stats["max"] = float(v.max())
        out[k] = stats
    return out


def _groups_for_chart(rows: Sequence[Dict[str, Any]],
                      true_rows: Sequence[Dict[str, Any]]) -> Dict[str, List[Dict[str, Any]]]:
    groups = {f"null: {k}": [r for r in rows if r.get("kind") == k] for k in KINDS}
    groups = {k: v for k, v in groups.items() if v}
    if true_rows:
        groups["true: matched"] = [r for r in true_rows if r.get("success")]
        groups["true: not matched"] = [r for r in true_rows if not r.get("matched")]
    return {k: v for k, v in groups.items() if v}


def _symlog(x: np.ndarray) -> np.ndarray:
    """sign(x) log10(1 + |x|): spreads values from -1000 to 1000 while keeping 0 and the sign."""
    return np.sign(x) * np.log10(1.0 + np.abs(x))


def _symlog_inverse(t: np.ndarray) -> np.ndarray:
    return np.sign(t) * (10.0 ** np.abs(t) - 1.0)


#: A panel is drawn on a symlog axis when its groups' median magnitudes differ by more than this
#: factor (true pairs' log10 NFA near -150 against the nulls' near +4; 35 inliers against 2).
SYMLOG_SPREAD = 10.0


def histogram_bins(groups: Sequence[np.ndarray], n_bins: int = 30) -> Tuple[np.ndarray, bool]:
    """(bin edges, symlog) shared by the groups of values (each (N,)) of one panel.

    Integers over a range of at most 60: one bin per integer. Groups whose median magnitudes
    differ by more than ``SYMLOG_SPREAD``: bins even in ``sign(x) log10(1 + |x|)`` and
    ``symlog`` True (the axis is drawn symlog, so both groups keep their shape). Else even bins.
    """
    groups = [np.asarray(g, np.float64) for g in groups if np.size(g)]
    v = np.concatenate(groups)
    lo, hi = float(v.min()), float(v.max())
    if np.all(v == np.round(v)) and hi - lo <= 60:
        return np.arange(lo - 0.5, hi + 1.5), False
    mags = [max(float(np.median(np.abs(g))), 1.0) for g in groups]
    if max(mags) > SYMLOG_SPREAD * min(mags):
        t = np.linspace(float(_symlog(np.array(lo))), float(_symlog(np.array(hi))), n_bins + 1)
        return _symlog_inverse(t), True
    return np.linspace(lo, hi if hi > lo else lo + 1.0, n_bins + 1), False


def plot_distributions(rows: Sequence[Dict[str, Any]], path: PathLike,
                       true_rows: Sequence[Dict[str, Any]] = (),
                       keys: Sequence[str] = CHART_KEYS, title: str = "",
                       size: Tuple[int, int] = (1200, 820)) -> np.ndarray:
    """Histograms of each charted evidence key: the nulls by kind, and true pairs if given.

    One panel per key present (``chart_keys``), the fraction of each group's runs that carry
    the key, per bin (so groups of different sizes compare); bins shared by the groups of a
    panel (``histogram_bins``; a symlog axis for keys spanning decades). One legend for the
    figure: each group with its number of runs. Drawn with the lab's matplotlib canvas
    (``plot._figure``), returned BGR and written to ``path``.
    """
    from matplotlib.lines import Line2D

    from ..chart import save
    from .plot import PALETTE, _figure, _to_bgr

    groups = _groups_for_chart(rows, true_rows)
    colours = {g: tuple(c / 255.0 for c in PALETTE[j % len(PALETTE)][::-1])
               for j, g in enumerate(groups)}
    keys = chart_keys([r for g in groups.values() for r in g], keys)
    fig = _figure((int(size[0]), int(size[1])))
    if not keys:
        ax = fig.add_subplot()
        ax.text(0.5, 0.5, "no data", transform=ax.transAxes, ha="center", va="center")
    n_col = min(3, max(len(keys), 1))
    n_row = max(int(math.ceil(len(keys) / n_col)), 1)
    for i, key in enumerate(keys):
        ax = fig.add_subplot(n_row, n_col, i + 1)
        values = {g: evidence_values(rs, key) for g, rs in groups.items()}
        bins, symlog = histogram_bins(list(values.values()))
        for g, v in values.items():
            if v.size:
                ax.hist(v, bins=bins, weights=np.full(v.size, 1.0 / v.size), histtype="step",
                        linewidth=2, color=colours[g])
        if symlog:
            ax.set_xscale("symlog", linthresh=1.0)
        ax.set_title(key + (" (symlog axis)" if symlog else ""), fontsize=10)
        ax.set_ylabel("fraction of runs with the key", fontsize=8)
        ax.tick_params(labelsize=8)
        ax.grid(True, color="0.9")
        ax.set_axisbelow(True)
    if groups:
        handles = [Line2D([], [], color=colours[g], linewidth=2) for g in groups]
        fig.legend(handles, [f"{g} ({len(rs)} runs)" for g, rs in groups.items()],
                   loc="lower center", ncol=min(len(groups), 4), fontsize=9, frameon=False)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    img = _to_bgr(fig)
    save(img, path)
    return img


def _fmt(v: Any, spec: str = ".2f") -> str:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return "-"
    return format(f, spec) if math.isfinite(f) else "-"


def format_summary(groups: Sequence[GroupSummary]) -> str:
    """The summary as a Markdown table."""
    out = ["| kind | order | runs | false claims | median s | max s | SIFT runs | "
           "SIFT median s | SIFT claims | errors |",
           "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for g in groups:
        out.append(f"| {g.kind} | {g.order} | {g.runs} | {g.false_claims} | "
                   f"{_fmt(g.median_seconds, '.3f')} | {_fmt(g.max_seconds, '.3f')} | "
                   f"{g.sift_runs} | {_fmt(g.sift_median_seconds, '.3f')} | {g.sift_claims} | "
                   f"{g.errors} |")
    return "\n".join(out) + "\n"


def format_percentiles(stats: Dict[str, Dict[str, Dict[str, Any]]]) -> str:
    """group -> key -> percentiles, as a Markdown table."""
    cols = ["min"] + [f"p{p}" for p in PERCENTILES] + ["max"]
    out = ["| runs | key | n | not finite | " + " | ".join(cols) + " |",
           "|---|---|---:|---:|" + "---:|" * len(cols)]
    for group, per_key in stats.items():
        for key, s in per_key.items():
            if not s["n"]:
                continue
            out.append(f"| {group} | {key} | {s['n']} | {s.get('not_finite', 0)} | "
                       + " | ".join(_fmt(s.get(c), ".3g") for c in cols) + " |")
    return "\n".join(out) + "\n"


def format_per_ratio(rows: Sequence[Dict[str, Any]]) -> str:
    """Null runs per ratio: runs, false claims, median and max time, SIFT's claims (Markdown)."""
    nulls = [r for r in rows if r.get("kind") in KINDS]
    out = ["| ratio | runs | false claims | median s | max s | SIFT median s | SIFT claims |",
           "|---:|---:|---:|---:|---:|---:|---:|"]
    for ratio in sorted({float(r["ratio"]) for r in nulls}):
        rs = [r for r in nulls if float(r["ratio"]) == ratio]
        sift = [r["sift"] for r in rs if isinstance(r.get("sift"), dict)]
        out.append(f"| {ratio:g} | {len(rs)} | {sum(bool(r.get('false_claim')) for r in rs)} | "
                   f"{_fmt(_median([r.get('seconds') for r in rs]), '.3f')} | "
                   f"{_fmt(_max([r.get('seconds') for r in rs]), '.3f')} | "
                   f"{_fmt(_median([x.get('seconds') for x in sift]), '.3f')} | "
                   f"{sum(bool(x.get('claimed')) for x in sift) if sift else '-'} |")
    return "\n".join(out) + "\n"


def format_reasons(rows: Sequence[Dict[str, Any]]) -> str:
    """Why the null runs gave no match: the reason's first words, counted per kind."""
    import collections

    def head(reason: str) -> str:
        text = str(reason or "").split(":")[0].split("(")[0].strip()
        return " ".join(text.split()[:8]) or "(matched: a false claim)"

    kinds = [k for k in KINDS if any(r.get("kind") == k for r in rows)]
    counts = {k: collections.Counter(head(r.get("reason", "")) for r in rows
                                     if r.get("kind") == k) for k in kinds}
    reasons = sorted({x for c in counts.values() for x in c},
                     key=lambda x: -sum(c[x] for c in counts.values()))
    out = ["| reason | " + " | ".join(kinds) + " |", "|---|" + "---:|" * len(kinds)]
    out += [f"| {x} | " + " | ".join(str(counts[k][x]) for k in kinds) + " |" for x in reasons]
    return "\n".join(out) + "\n"


def _time_sentence(groups: Sequence[GroupSummary]) -> str:
    """One line comparing the nulls' median time with SIFT's on the same runs ("" without)."""
    g = next((g for g in groups if g.kind == "all nulls"), None)
    if g is None or not g.sift_runs or not math.isfinite(g.sift_median_seconds):
        return ""
    return (f"\nNo-match median time: scalematch {g.median_seconds:.2f} s, SIFT "
            f"{g.sift_median_seconds:.2f} s on the same {g.sift_runs} runs "
            f"({g.median_seconds / g.sift_median_seconds:.1f}x); SIFT claimed a match on "
            f"{g.sift_claims} of them (every one false).\n")


def false_claims(rows: Sequence[Dict[str, Any]]) -> List[Dict[str, Any]]:
    """The rows claiming a match they should not have (nulls: any; true pairs: > 3 px off)."""
    return [r for r in rows if r.get("false_claim")]


# --------------------------------------------------------------------------------------------
# The run
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class NullReport:
    """What ``run_nulls`` produced."""

    rows: Tuple[Dict[str, Any], ...] = field(repr=False)  #: the null runs
    true_rows: Tuple[Dict[str, Any], ...] = field(repr=False)
    groups: Tuple[GroupSummary, ...]
    stats: Dict[str, Dict[str, Dict[str, Any]]] = field(repr=False)
    settings: Dict[str, Any] = field(repr=False)
    rows_path: Path
    chart_path: Optional[Path]
    text: str = field(repr=False)
    false_claims_path: Optional[Path] = None  #: the picture of the false claims, if any


def _log_none(_: str) -> None:
    pass


def run_nulls(*, shared: Optional[PathLike] = None, out_dir: PathLike = DEFAULT_OUT,
              ratios: Sequence[float] = RATIOS, photos: Optional[int] = None, seed: int = 0,
              mode: str = "default", jobs: int = 1, limit: Optional[int] = None,
              sift: bool = False, true_count: int = 0,
              true_rows_path: Optional[PathLike] = None, max_minutes: Optional[float] = None,
              command: str = "", log: Callable[[str], None] = _log_none) -> NullReport:
    """Make the null pairs, run them in both orders, write rows, summary and chart.

    Parameters
    ----------
    shared : path, optional
        The shared folder (``datasets.find_shared()`` when None).
    out_dir : path
        Pairs (``pairs-seed<seed>/``), rows (``nulls_<mode>_seed<seed>.jsonl``, and
        ``true_<mode>_seed<seed>.jsonl``), ``nulls_<mode>.png`` and ``nulls_<mode>.json``.
    ratios, photos, seed
        The pairs: ratios, the first ``photos`` photos (sorted by name; None: all), the seed.
    mode : str
        A preset of ``NULL_MODES``: "default", "paper" (``Config.paper()``), "tilt-4"
        (the default without its views at tilts 6 and 8),
        "budget-1s" (the default with a 1 s time budget), "affine" and "homography" (the
        default's answer allowed no further than that model), "homography-searched" (a
        homography searched at every scale), "fundamental" (the default searching for it) or
        "no-views" (the default without tilted views, ``--no-views``).
    jobs : int
        Worker processes (1: this process).
    limit : int, optional
        Only the first ``limit`` pairs of the fixed run order (``null_specs``): a balanced
        sample; each is run in both orders.
    sift : bool
        Also run the SIFT reference on each run, alternating which goes first.
    true_count : int
        Also run this many true zoom pairs (``true_specs``) through the same recorder.
    true_rows_path : path, optional
        A JSONL of true-pair rows from an earlier run to overlay (used when ``true_count`` 0).
    max_minutes : float, optional
        Start no new run after this many minutes (null runs first, then true runs).
    """
    if mode not in NULL_MODES:
        raise ValueError(f"mode must be one of {NULL_MODES}, got {mode!r}")
    shared_path = Path(shared) if shared is not None else find_shared()
    if shared_path is None or not (shared_path / "data" / "photos").is_dir():
        raise ValueError("the shared data folder was not found: pass shared=... or set "
                         "SCALEMATCH_SHARED to the folder holding data/photos")
    paths = list_photos(shared_path)
    if photos is not None:
        paths = paths[:max(int(photos), 0)]
    if len({scene_of(p.name) for p in paths}) < 2:
        raise ValueError("the null set needs photos of at least two scenes")
    photo_dir = shared_path / "data" / "photos"
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    deadline = None if max_minutes is None else time.monotonic() + 60.0 * float(max_minutes)
    load_at_start = _load_average()

    specs = null_specs([p.name for p in paths], ratios, seed)
    full_set = len(specs)
    if limit is not None:
        specs = specs[:max(int(limit), 0)]
    pair_dir = out / f"pairs-seed{seed}"
    entries = ensure_pairs(specs, pair_dir, photo_dir, log)
    log(f"{len(specs)} null pairs ({sum(s.kind == 'unrelated' for s in specs)} unrelated, "
        f"{sum(s.kind == 'same-photo' for s in specs)} same-photo), {2 * len(specs)} runs")
    tasks = make_tasks([entries[s.pair_id] for s in specs], pair_dir, mode, sift, seed)
    rows_path = out / f"nulls_{mode}_seed{seed}.jsonl"
    wanted = {t["run_id"] for t in tasks}
    resumed = sum(r.get("run_id") in wanted for r in load_rows(rows_path))
    rows = [r for r in execute(tasks, rows_path, jobs, deadline=deadline, log=log)
            if r.get("run_id") in wanted]

    true_rows: List[Dict[str, Any]] = []
    if true_count:
        tspecs = true_specs([p.name for p in paths], true_count, ratios, seed)
        tentries = ensure_pairs(tspecs, pair_dir, photo_dir, log)
        ttasks = make_tasks([tentries[s.pair_id] for s in tspecs], pair_dir, mode, sift, seed)
        twanted = {t["run_id"] for t in ttasks}
        true_rows = [r for r in execute(ttasks, out / f"true_{mode}_seed{seed}.jsonl", jobs,
                                        deadline=deadline, log=log)
                     if r.get("run_id") in twanted]
    elif true_rows_path is not None:
        true_rows = [r for r in load_rows(true_rows_path) if r.get("kind") == TRUE_KIND]

    add_footprint_ncc(rows, entries, pair_dir)
    if true_count:
        add_footprint_ncc(true_rows, tentries, pair_dir)
    groups = summarise(rows + true_rows)
    keys = chart_keys(rows + true_rows)
    stats: Dict[str, Dict[str, Dict[str, Any]]] = {}
    for kind in KINDS:
        rs = [r for r in rows if r.get("kind") == kind]
        if rs:
            stats[f"null {kind}"] = percentiles(rs, keys)
    if true_rows:
        stats["true, matched"] = percentiles([r for r in true_rows if r.get("success")], keys)
        stats["true, no match"] = percentiles([r for r in true_rows if not r.get("matched")], keys)
    chart_path: Optional[Path] = out / f"nulls_{mode}.png"
    try:
        plot_distributions(rows, chart_path, true_rows, keys,
                           title=f"Evidence on {len(rows)} null runs ({mode} mode)"
                           + (f" and {len(true_rows)} true runs" if true_rows else ""))
    except ImportError as exc:
        log(f"note: no chart ({exc})")
        chart_path = None
    fc_path: Optional[Path] = out / f"nulls_{mode}_false_claims.png"
    all_entries = dict(entries, **(tentries if true_count else {}))
    if false_claim_figure(rows + true_rows, all_entries, pair_dir, fc_path) is None:
        fc_path = None
    from .bench import _git_commit, machine

    settings = {"command": command, "seed": seed, "mode": mode,
                "ratios": [float(r) for r in ratios],
                "photos": [p.name for p in paths], "pairs": len(specs), "runs_planned": len(tasks),
                "pairs_in_full_set": full_set, "runs_resumed": resumed,
                "limit": limit, "jobs": jobs, "sift": sift, "true_count": true_count,
                "max_minutes": max_minutes, "machine": machine(),
                "load_average_at_start": load_at_start, "opencv": cv2.__version__,
                "numpy": np.__version__, "python": platform.python_version(),
                "commit": _git_commit(), "opencv_threads": cv2.getNumThreads(),
                "run_commits": dict(Counter(r.get("commit") or "" for r in rows + true_rows)),
                "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
                "keys_recorded": sorted({k for r in rows for k in (r.get("evidence") or {})}),
                "pairs_folder": str(pair_dir), "rows_path": str(rows_path)}
    text = ("Runs (a false claim: any match on a null pair; on a true pair, a match more than "
            "3 px off)\n\n" + format_summary(groups) + _time_sentence(groups)
            + "\nNull runs per ratio\n\n" + format_per_ratio(rows)
            + "\nWhy the null runs gave no match (the reason's first words)\n\n"
            + format_reasons(rows)
            + "\nEvidence percentiles (runs with the key; a no-match reports the evidence of its "
            "first search: the order given, plain views)\n\n" + format_percentiles(stats))
    bad = false_claims(rows + true_rows)
    text += f"\nFalse claims: {len(bad)}\n" + "".join(
        f"- `{r['run_id']}`: ratio {_fmt(r.get('resolution_ratio'))}, rotation "
        f"{_fmt(r.get('rotation_deg'), '.1f')} deg, {r.get('inliers')} inliers, footprint NCC "
        f"{_fmt(r.get('footprint_ncc'))}; SIFT "
        f"{'claimed too' if (r.get('sift') or {}).get('claimed') else 'no claim'}; transform "
        f"{r.get('transform')}; evidence {r.get('evidence')}\n" for r in bad)
    with open(out / f"nulls_{mode}.json", "w") as f:
        json.dump({"settings": settings, "groups": [asdict(g) for g in groups], "stats": stats,
                   "false_claims": bad}, f, indent=1, default=str)
    return NullReport(rows=tuple(rows), true_rows=tuple(true_rows), groups=groups, stats=stats,
                      settings=settings, rows_path=rows_path, chart_path=chart_path, text=text,
                      false_claims_path=fc_path)


def _load_average() -> Optional[float]:
    try:
        return round(os.getloadavg()[0], 2)
    except (OSError, AttributeError):
        return None


def doc_section(mode: str) -> Tuple[str, str]:
    """(section, command) of ``mode``'s block of the null-set page: its markers are
    ``realpairs.markers(*doc_section(mode))``, "<!-- nulls MODE: begin (written by scalematch
    lab nulls --mode MODE) -->" and "<!-- nulls MODE: end -->"."""
    return f"nulls {mode}", f"scalematch lab nulls --mode {mode}"


def write_nulls_doc(report: NullReport, path: PathLike = "docs/results/NULLS.md") -> Path:
    """Write the run's mode's section of ``path`` (Markdown): command, machine, the tables, the
    chart. Only the block between the mode's markers (:func:`doc_section`) is rewritten, or
    appended when they are absent: each mode keeps its own section, and the page's
    introduction stays as it is. The chart is copied next to the page as ``<page stem>.png``
    for the default mode and ``<page stem>-<mode>.png`` for the others, lower case
    (docs/results/nulls.png, docs/results/nulls-no-views.png). Generated: re-run the command rather
    than edit the section."""
    from .realpairs import write_section

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    if not p.is_file():
        p.write_text("# The null set: pairs with no answer\n")
    s = report.settings
    mode = s["mode"]
    stem = p.stem.lower() + ("" if mode == "default" else f"-{mode}")
    runs = len(report.rows)
    lines = [
        f"## Mode {mode}", "",
        f"- Command: `{s['command']}`",
        f"- Date: {s['date']}; commit {s['commit'] or 'unknown'} (the page's); "
        f"{made_on(s.get('run_commits') or {})}",
        f"- Machine: {s['machine']}; load average at the start {s['load_average_at_start']} "
        "(the cores are shared with other work: times are wall-clock)",
        f"- Software: Python {s['python']}, OpenCV {s['opencv']}, NumPy {s['numpy']}; "
        f"{s['jobs']} worker(s)" + (", OpenCV's default threads in the one worker"
                                   if s["jobs"] == 1 else ", one OpenCV thread each"),
        f"- Mode {s['mode']}; seed {s['seed']}; ratios "
        f"{', '.join(f'{r:g}' for r in s['ratios'])}; {len(s['photos'])} photos",
        f"- The full null set: {s.get('pairs_in_full_set', s['pairs'])} pairs "
        f"({2 * s.get('pairs_in_full_set', s['pairs'])} runs); this run: the first "
        f"{s['pairs']} pairs of the fixed run order ({s['runs_planned']} runs), {runs} runs done"
        + (f", {s['runs_resumed']} of them by earlier invocations of the same command, resumed "
           "from the rows file (each run's time is measured where it ran; the load average "
           "above is this invocation's)" if s.get("runs_resumed") else "")
        + ("" if runs >= s["runs_planned"] else
           f". **Not the whole set**: the time budget stopped the run after {runs} runs, a "
           "prefix of the fixed, seeded order (kinds alternate, photos and ratios shuffled), "
           "so a balanced sample; re-run the command to complete it")
        + ("" if s["pairs"] >= s.get("pairs_in_full_set", s["pairs"]) else
           " (a prefix of the fixed, seeded run order: the kinds alternate, photos and ratios "
           "are shuffled, so it is a balanced sample)"),
        ("- SIFT: the reference (OpenCV SIFT, ratio test 0.8, RANSAC similarity at 3 px, "
         "claims from 4 inliers) on the same images in the same order, in the same process, "
         "alternately before and after scalematch.") if s["sift"] else "- SIFT not run.",
        f"- Evidence keys recorded: {', '.join(f'`{k}`' for k in s['keys_recorded']) or 'none'}",
        ""]
    if report.chart_path is not None and Path(report.chart_path).is_file():
        png = stem + ".png"
        shutil.copyfile(report.chart_path, p.parent / png)
        lines += [f"![evidence distributions on null and true runs]({png})", ""]
    lines += [report.text, ""]
    if report.false_claims_path is not None and Path(report.false_claims_path).is_file():
        png = stem + "_false_claims.png"
        shutil.copyfile(report.false_claims_path, p.parent / png)
        lines += ["Each false claim: the low image under the claimed footprint (left), the high "
                  "image placed there by the claim (right).", "",
                  f"![the false claims]({png})", ""]
    lines += ["Photos: " + ", ".join(f"`{n}`" for n in s["photos"]), ""]
    write_section(p, "\n".join(lines), *doc_section(mode))
    return p


# --------------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------------

@click.command("nulls")
@click.option("--shared", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=None, help="Shared data folder (default $SCALEMATCH_SHARED or ../shared).")
@click.option("--out-dir", type=click.Path(file_okay=False, path_type=Path), default=DEFAULT_OUT,
              show_default=True, help="Pairs (PNG + manifest), rows (JSONL), summary, chart.")
@click.option("--ratios", default=",".join(f"{r:g}" for r in RATIOS), show_default=True,
              help="Zoom ratios of the pairs, comma-separated.")
@click.option("--photos", type=click.IntRange(min=2), default=None,
              help="Use only the first N photos (sorted by name). Default: all.")
@click.option("--seed", type=int, default=0, show_default=True, help="The one seed of the run.")
@click.option("--mode", type=click.Choice(NULL_MODES), default="default",
              show_default=True, help="scalematch's configuration (a preset: paper is "
              "Config.paper(), tilt-4 the default without its views at tilts 6 and 8, budget-1s "
              "the default with --time-budget 1, affine and homography the default with --model "
              "affine or homography, homography-searched a homography searched at every "
              "scale, fundamental the default with --model fundamental, no-views the default "
              "with --no-views).")
@click.option("--jobs", type=click.IntRange(min=1), default=1, show_default=True,
              help="Worker processes (more than 1: one OpenCV thread each).")
@click.option("--limit", type=click.IntRange(min=1), default=None,
              help="Only the first N pairs of the fixed, balanced run order (2N runs).")
@click.option("--sample", is_flag=True, help="A small fixed sample: --limit 3 (6 runs).")
@click.option("--sift", is_flag=True, help="Also time SIFT + RANSAC on each run (alternating).")
@click.option("--true", "true_count", type=click.IntRange(min=0), default=0, show_default=True,
              help="Also run N true zoom pairs through the same recorder, for the overlay.")
@click.option("--true-rows", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              default=None, help="Overlay the true-pair rows of this JSONL (from --true).")
@click.option("--max-minutes", type=click.FloatRange(min=0), default=None,
              help="Start no new run after this many minutes (resume later).")
@click.option("--write-doc", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write the mode's section of this Markdown page (e.g. "
                   "docs/results/NULLS.md) and its chart.")
@click.option("--silent", is_flag=True, help="No progress lines (the tables are still printed).")
@click.pass_context
def nulls_command(ctx, shared, out_dir, ratios, photos, seed, mode, jobs, limit, sample, sift,
                  true_count, true_rows, max_minutes, write_doc, silent):
    """Run scalematch on pairs that have no answer (both orders) and chart the evidence.

    Null pairs: unrelated photos, and two disjoint halves of one photo (same texture, no
    answer), at ratios 2 to 16, deterministic from the seed; re-running resumes. Exit code 1
    when any false claim was found.

    Example: scalematch lab nulls --sample --sift
    """
    from .bench import _command_line, _csv_floats

    log = (lambda s: None) if silent else (lambda s: click.echo(s, err=True))
    ratio_list = _csv_floats(ctx, None, ratios)
    if not ratio_list or min(ratio_list) < 1:
        raise click.BadParameter("give ratios >= 1, e.g. 2,4,8,16", param_hint="--ratios")
    if sample and limit is None:
        limit = 3
    shared = require_shared(shared)
    try:
        report = run_nulls(shared=shared, out_dir=out_dir, ratios=ratio_list, photos=photos,
                           seed=seed, mode=mode, jobs=jobs, limit=limit, sift=sift,
                           true_count=true_count, true_rows_path=true_rows,
                           max_minutes=max_minutes, command=_command_line(ctx), log=log)
    except ValueError as exc:
        raise click.ClickException(str(exc))
    click.echo(report.text)
    click.echo(f"rows: {report.rows_path}")
    if report.chart_path is not None:
        click.echo(f"chart: {report.chart_path}")
    if write_doc is not None:
        click.echo(f"wrote {write_nulls_doc(report, write_doc)}")
    if false_claims(list(report.rows) + list(report.true_rows)):
        ctx.exit(1)
