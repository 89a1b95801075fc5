"""The fundamental-matrix benchmark on the real 3-D pairs of ``shared/data/ef``.

Protocol (../shared/EVALUATION.md, "Real pairs"; ``shared/data/ef/SOURCES.md``): eight pairs of
3-D scenes (parallax: no plane map), each with about ten hand-clicked correspondences
``x_A y_A x_B y_B``. A fundamental matrix is judged by the mean symmetric epipolar distance of
the clicked points (:func:`symmetric_epipolar_error`), px; under ``SOLVED_PX`` solves the pair.

Every F here is in one convention, written once: ``x_B^T F x_A = 0`` (A -> B). scalematch
answers ``x_coarser^T F x_finer = 0`` (result.py) with ``order`` saying which image given is the
coarser; :func:`a_to_b` turns that round. Each pair runs in both orders (A given first, then B),
for three methods in the same run:

* ``scalematch``: ``match(first, second, Config(model="fundamental"))``, scored;
* ``plane``: scalematch's default configuration (a plane map; on a 3-D scene the dominant
  plane's, ``evidence.parallax`` true): matched / parallax / inliers recorded, not scored;
* ``sift-magsac``: OpenCV SIFT, ratio test 0.8 (the second image given is the query, as in
  ``baselines``), ``cv2.findFundamentalMat(pts_A, pts_B, cv2.USAC_MAGSAC, 1.0, 0.9999, 10000)``.

The data is read at run time from the shared folder and never copied into the repository.
A benchmark, not a test: nothing here asserts a time. ``scalematch lab ef-pairs --help``.
"""

from __future__ import annotations

import json
import math
import os
import platform
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Union

import click
import cv2
import numpy as np

from ..geometry import epipolar_distances as geometric_distances
from ..result import Direction
from .baselines import RATIO_TEST, detect_and_describe, make_detector, ratio_matches, to_uint8
from .datasets import require_shared, shared_option, shared_subfolder

PathLike = Union[str, Path]

#: The pairs' folder inside the shared folder (EVALUATION.md, "Real pairs")
EF_SUBDIR = Path("data") / "ef"
#: Mean symmetric epipolar distance under which a pair is solved, px (ef/SOURCES.md)
SOLVED_PX = 3.0
#: A claimed F farther off than this, px, is a wrong F claimed (the issue asking for this
#: benchmark; between ``SOLVED_PX`` and it, a claim is neither solved nor plainly wrong)
WRONG_PX = 10.0
#: The reference's MAGSAC++ settings: inlier threshold px, confidence, iterations
#: (ef/SOURCES.md: ``cv2.findFundamentalMat(..., cv2.USAC_MAGSAC, 1.0, 0.9999, 10000)``)
MAGSAC_PX = 1.0
MAGSAC_CONFIDENCE = 0.9999
MAGSAC_ITERATIONS = 10000
#: Fewest inliers for the reference to claim an F: the sample of the 8-point algorithm
#: (Hartley, "In defense of the eight-point algorithm", PAMI 1997); fewer support nothing more
#: than the minimal sample itself
MIN_F_INLIERS = 8
#: The orders a pair is given in: A first (the ``low`` argument), then B first
ORDERS = ("A,B", "B,A")
#: The methods, in the order they are reported (see the module docstring)
METHODS = ("scalematch", "plane", "sift-magsac")


# --------------------------------------------------------------------------------------------
# Reading a pair
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class EfPair:
    """One pair of ``shared/data/ef``: two grey images and the clicked points."""

    name: str
    a: np.ndarray = field(repr=False)  #: (H, W) float32 grey levels, image A
    b: np.ndarray = field(repr=False)  #: (H, W) float32 grey levels, image B
    points: np.ndarray = field(repr=False)  #: (N, 4) float64 x_A, y_A, x_B, y_B, px


def read_points(path: PathLike) -> np.ndarray:
    """The clicked points of a pair: (N, 4) float64 ``x_A y_A x_B y_B`` per line, px.

    Lines starting with ``#`` are comments. Raises ``ValueError`` when a line does not hold
    four numbers or there is no point.

    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "p_points.txt")
    >>> _ = open(path, "w").write("# x_A y_A x_B y_B\\n1 2 3 4\\n5.5 6 7 8\\n")
    >>> read_points(path).tolist()
    [[1.0, 2.0, 3.0, 4.0], [5.5, 6.0, 7.0, 8.0]]
    """
    rows = []
    for k, line in enumerate(Path(path).read_text().splitlines(), start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        try:
            values = [float(v) for v in text.split()]
        except ValueError:
            values = []
        if len(values) != 4:
            raise ValueError(f"{path}:{k}: expected four numbers 'x_A y_A x_B y_B', got {text!r}")
        rows.append(values)
    if not rows:
        raise ValueError(f"{path}: no point; expected lines 'x_A y_A x_B y_B'")
    return np.array(rows, dtype=np.float64)


def ef_folder(shared: Optional[PathLike] = None) -> Optional[Path]:
    """``<shared>/data/ef`` (``shared`` default: :func:`datasets.find_shared`); None if absent."""
    return shared_subfolder(EF_SUBDIR, shared)


def pair_names(folder: PathLike) -> List[str]:
    """The pairs of ``folder``: the NAME of each ``NAME_points.txt``, sorted."""
    return sorted(p.name[: -len("_points.txt")] for p in Path(folder).glob("*_points.txt"))


def image_path(folder: PathLike, name: str, side: str) -> Path:
    """The one file ``NAME_<side>.*`` of ``folder`` (side "A" or "B")."""
    found = sorted(Path(folder).glob(f"{name}_{side}.*"))
    if len(found) != 1:
        raise ValueError(f"{folder}: expected one image {name}_{side}.*, found {len(found)}")
    return found[0]


def load_pair(folder: PathLike, name: str) -> EfPair:
    """The pair ``name`` of ``folder``: images A and B as grey levels and the clicked points."""
    from ..imageio import read_grey

    return EfPair(name, read_grey(image_path(folder, name, "A")),
                  read_grey(image_path(folder, name, "B")),
                  read_points(Path(folder) / f"{name}_points.txt"))


# --------------------------------------------------------------------------------------------
# The score and the convention
# --------------------------------------------------------------------------------------------

def epipolar_distances(f: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, 2) distances, px, for an F with ``x_B^T F x_A = 0``: column 0, of x_B to the line
    ``F x_A``; column 1, of x_A to the line ``F^T x_B`` (:func:`scalematch.geometry.epipolar_distances`).

    Parameters
    ----------
    f : (3, 3) array
    points : (N, 4) array
        x_A, y_A, x_B, y_B per row.

    >>> f = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # a rectified pair: y_B = y_A
    >>> epipolar_distances(f, np.array([[10, 20, 30, 20], [5, 5, 50, 7]], float)).tolist()
    [[0.0, 0.0], [2.0, 2.0]]
    """
    f = np.asarray(f, np.float64)
    if f.shape != (3, 3):
        raise ValueError(f"F must be 3x3, got shape {f.shape}")
    pts = np.asarray(points, np.float64).reshape(-1, 4)
    return geometric_distances(f, pts[:, :2], pts[:, 2:])


def symmetric_epipolar_error(f: Optional[np.ndarray], points: np.ndarray) -> float:
    """Mean symmetric epipolar distance, px, of ``points`` (N, 4: x_A, y_A, x_B, y_B) for an F
    with ``x_B^T F x_A = 0`` (ef/SOURCES.md); ``inf`` when there is no F (no claim).

    >>> f = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)
    >>> symmetric_epipolar_error(f, np.array([[10, 20, 30, 20], [5, 5, 50, 7]], float))
    1.0
    """
    if f is None:
        return math.inf
    return float(np.mean(epipolar_distances(f, points)))


def a_to_b(f: np.ndarray, order: Union[Direction, str], a_first: bool) -> np.ndarray:
    """scalematch's F (``x_coarser^T F x_finer = 0``, result.py) in the A -> B convention
    ``x_B^T F x_A = 0``.

    ``order`` is the result's: GIVEN, the first image given is the coarser one; SWAPPED, the
    second is. ``a_first``: A was given first. F is kept when A is the finer image, transposed
    when B is.

    >>> f = np.arange(9.0).reshape(3, 3)
    >>> bool((a_to_b(f, "given", a_first=True) == f.T).all())   # A coarser, B finer
    True
    >>> bool((a_to_b(f, "swapped", a_first=True) == f).all())   # A finer
    True
    """
    f = np.asarray(f, np.float64)
    return f if coarser_of(order, a_first) == "B" else f.T


def coarser_of(order: Union[Direction, str], a_first: bool) -> str:
    """Which image, "A" or "B", a result of ``order`` took as the coarser one (``a_first``: A
    was given first).

    >>> coarser_of("given", a_first=True), coarser_of("swapped", a_first=True)
    ('A', 'B')
    """
    return "A" if (Direction(order) is Direction.GIVEN) == a_first else "B"


# --------------------------------------------------------------------------------------------
# Methods: (pair, a_first) -> Run
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Run:
    """What one method answered on one pair in one order."""

    method: str  #: one of METHODS
    f: Optional[np.ndarray] = field(repr=False)  #: x_B^T F x_A = 0; None: no F claimed
    claimed: bool  #: an answer was given (for "plane": a plane map, ``f`` None)
    inliers: int  #: the answer's inliers (0 when none)
    seconds: float  #: wall time of the method on the pair
    matches: int = 0  #: sift-magsac: matches surviving the ratio test
    parallax: bool = False  #: plane: ``evidence.parallax`` (a 3-D scene seen)
    model: str = ""  #: scalematch, plane: the result's model
    coarser: str = ""  #: scalematch, plane: the image, "A" or "B", taken as the coarser one
    reason: str = ""  #: why nothing was claimed ("" when claimed)


def _ordered(pair: EfPair, a_first: bool):
    return (pair.a, pair.b) if a_first else (pair.b, pair.a)


def run_scalematch(pair: EfPair, a_first: bool, seed: int = 0) -> Run:
    """``match(first, second, Config(model="fundamental", seed=seed))``, F turned to A -> B."""
    from ..config import Config
    from ..pipeline import match

    t0 = time.perf_counter()
    r = match(*_ordered(pair, a_first), Config(model="fundamental", seed=seed))
    seconds = time.perf_counter() - t0
    # without parallax the plane map answers: no epipolar geometry is claimed
    claimed = r.matched and r.model == "fundamental"
    f = a_to_b(r.transform, r.order, a_first) if claimed else None
    reason = r.reason if not r.matched else "" if claimed else \
        f"no parallax: answered with its plane map ({r.model}, {r.n_inliers} inliers)"
    return Run("scalematch", f, claimed, r.n_inliers if claimed else 0, seconds, model=r.model,
               coarser=coarser_of(r.order, a_first), reason=reason)


def run_plane(pair: EfPair, a_first: bool, seed: int = 0) -> Run:
    """scalematch's default configuration: its plane map is recorded, not scored."""
    from ..config import Config
    from ..pipeline import match

    t0 = time.perf_counter()
    r = match(*_ordered(pair, a_first), Config(seed=seed))
    return Run("plane", None, r.matched, r.n_inliers, time.perf_counter() - t0,
               parallax=bool(r.evidence.parallax), model=r.model,
               coarser=coarser_of(r.order, a_first), reason=r.reason)


def fit_fundamental(pts_a: np.ndarray, pts_b: np.ndarray, seed: int = 0):
    """The reference's F (``x_B^T F x_A = 0``) and its inlier count: USAC_MAGSAC with the
    settings of ef/SOURCES.md, OpenCV's RNG seeded (as ``baselines.estimate``). (None, n)
    when fewer than ``MIN_F_INLIERS`` inliers support it."""
    if len(pts_a) < MIN_F_INLIERS:
        return None, 0
    cv2.setRNGSeed(int(seed))
    f, mask = cv2.findFundamentalMat(np.ascontiguousarray(pts_a, np.float32),
                                     np.ascontiguousarray(pts_b, np.float32), cv2.USAC_MAGSAC,
                                     MAGSAC_PX, MAGSAC_CONFIDENCE, MAGSAC_ITERATIONS)
    n = int(mask.sum()) if mask is not None else 0
    if f is None or f.shape[0] < 3 or n < MIN_F_INLIERS or not np.all(np.isfinite(f[:3])):
        return None, n
    return np.asarray(f[:3], np.float64), n


def run_sift_magsac(pair: EfPair, a_first: bool, seed: int = 0) -> Run:
    """OpenCV SIFT, ratio test 0.8 (the second image given is the query), then
    :func:`fit_fundamental` on the matches as (A, B) points."""
    detector, norm = make_detector("sift")
    first, second = _ordered(pair, a_first)
    t0 = time.perf_counter()
    xy_1, d_1 = detect_and_describe(detector, to_uint8(first))
    xy_2, d_2 = detect_and_describe(detector, to_uint8(second))
    m = ratio_matches(d_2, d_1, norm, RATIO_TEST)  # (second, first) indices
    pts_1, pts_2 = xy_1[m[:, 1]], xy_2[m[:, 0]]
    pts_a, pts_b = (pts_1, pts_2) if a_first else (pts_2, pts_1)
    f, n = fit_fundamental(pts_a, pts_b, seed)
    return Run("sift-magsac", f, f is not None, n, time.perf_counter() - t0, matches=int(len(m)),
               reason="" if f is not None else f"{n} inliers < {MIN_F_INLIERS}")


RUNNERS = {"scalematch": run_scalematch, "plane": run_plane, "sift-magsac": run_sift_magsac}


def run_orders(pair: EfPair, methods: Sequence[str], row_of_run, seed: int = 0,
               log=lambda s: None) -> List[Dict[str, Any]]:
    """The rows of ``methods`` (of ``RUNNERS``) on ``pair`` in both orders, alternating (each
    order, each method), ``row_of_run(order, run)`` making each row; a progress line per run
    through ``log``."""
    rows = []
    for order in ORDERS:
        for m in methods:
            row = row_of_run(order, RUNNERS[m](pair, order == ORDERS[0], seed))
            rows.append(row)
            log(f"{pair.name} {order} {m:11s} claimed {row['claimed']!s:5s} error "
                f"{_err(row['error_px']):>8s} px, {row['inliers']} inliers, "
                f"{row['seconds']:.1f} s")
    return rows


# --------------------------------------------------------------------------------------------
# Rows, summary, table
# --------------------------------------------------------------------------------------------

def row_of(pair: EfPair, order: str, run: Run) -> Dict[str, Any]:
    """One JSON row: the run's figures and its score (NaN for "plane", which is not scored)."""
    scored = run.method != "plane"
    err = symmetric_epipolar_error(run.f, pair.points) if scored else math.nan
    row = {k: v for k, v in asdict(run).items() if k != "f"}
    return {"pair": pair.name, "order": order, **row, "error_px": err,
            "solved": bool(scored and err < SOLVED_PX),
            "wrong": bool(scored and run.claimed and err > WRONG_PX),
            "f": None if run.f is None else (run.f / np.linalg.norm(run.f)).tolist()}


def summarise(rows: Sequence[Dict[str, Any]]) -> List[Dict[str, Any]]:
    """Per method: runs, claimed, solved (< ``SOLVED_PX``), the median error of the solved,
    wrong Fs claimed (> ``WRONG_PX``), parallax seen (plane) and the median time."""
    out = []
    for m in METHODS:
        rs = [r for r in rows if r["method"] == m]
        if not rs:
            continue
        ok = [r["error_px"] for r in rs if r["solved"]]
        out.append({"method": m, "runs": len(rs), "claimed": sum(r["claimed"] for r in rs),
                    "solved": len(ok), "median_error_px": float(np.median(ok)) if ok else math.nan,
                    "wrong": sum(r["wrong"] for r in rs),
                    "parallax": sum(bool(r["parallax"]) for r in rs),
                    "median_s": float(np.median([r["seconds"] for r in rs]))})
    return out


def _err(v: float) -> str:
    return "-" if not math.isfinite(v) else f"{v:.2f}"


def markdown(rows: Sequence[Dict[str, Any]], meta: Dict[str, Any]) -> str:
    """The Markdown section: the run, one line per pair and order, and the summary."""
    by = {(r["pair"], r["order"], r["method"]): r for r in rows}
    lines = ["## Fundamental matrix on real 3-D pairs (ef)", "",
             "Protocol: ../shared/EVALUATION.md, \"Real pairs\", and ../shared/data/ef/SOURCES.md: "
             "the mean symmetric epipolar distance of the hand-clicked points, px (solved: "
             f"< {SOLVED_PX:g} px; a wrong F claimed: > {WRONG_PX:g} px). scalematch: "
             "`Config(model=\"fundamental\")`; plane: the default configuration (a plane map, not "
             "scored); SIFT: ratio test 0.8 + `cv2.findFundamentalMat(pts_A, pts_B, "
             f"cv2.USAC_MAGSAC, {MAGSAC_PX:g}, {MAGSAC_CONFIDENCE:g}, {MAGSAC_ITERATIONS})`, "
             f"at least {MIN_F_INLIERS} inliers. Order A,B: A given first.", "",
             f"- `{meta.get('command', '?')}`: {meta.get('date', '?')}, {meta.get('machine', '?')}, "
             f"load average at start {meta.get('load', '?')}, seed {meta.get('seed', '?')}, "
             f"OpenCV {meta.get('opencv', '?')}", "",
             "| pair | order | scalematch F error px | inliers | s | plane: matched | parallax "
             "| inliers | SIFT+MAGSAC error px | inliers | matches | s |",
             "|---|---|---:|---:|---:|---|---|---:|---:|---:|---:|---:|"]
    keys = sorted({(r["pair"], r["order"]) for r in rows},
                  key=lambda k: (k[0].lower(), ORDERS.index(k[1])))
    for p, o in keys:
        s, pl, sf = (by.get((p, o, m)) for m in METHODS)
        cells = [p, o]
        cells += ([_err(s["error_px"]) if s["claimed"] else "no F", str(s["inliers"]),
                   f"{s['seconds']:.1f}"] if s else ["", "", ""])
        cells += ([("yes" if pl["claimed"] else "no"), ("yes" if pl["parallax"] else "no"),
                   str(pl["inliers"])] if pl else ["", "", ""])
        cells += ([_err(sf["error_px"]) if sf["claimed"] else "no F", str(sf["inliers"]),
                   str(sf["matches"]), f"{sf['seconds']:.1f}"] if sf else ["", "", "", ""])
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "| method | runs | claimed | solved | median error px of solved | wrong F "
              "claimed | parallax seen | median s |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in summarise(rows):
        plane = r["method"] == "plane"
        lines.append(f"| {r['method']} | {r['runs']} | {r['claimed']} | "
                     f"{'-' if plane else r['solved']} | {_err(r['median_error_px'])} | "
                     f"{'-' if plane else r['wrong']} | {r['parallax'] if plane else '-'} | "
                     f"{r['median_s']:.1f} |")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------------
# Command
# --------------------------------------------------------------------------------------------

@click.command("ef-pairs", context_settings={"help_option_names": ["-h", "--help"]})
@shared_option
@click.option("--pairs", default="", help="Comma-separated pair names (default: all of data/ef).")
@click.option("--methods", default=",".join(METHODS), show_default=True)
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seeds scalematch (Config.seed) and OpenCV's RNG (MAGSAC).")
@click.option("--out-dir", type=click.Path(file_okay=False, path_type=Path),
              default=Path("bench-out/ef"), show_default=True)
@click.option("--write-doc", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write the tables into this Markdown file (its ef-pairs section).")
@click.option("--silent", is_flag=True, help="No progress lines on stderr.")
def ef_pairs_command(shared, pairs, methods, seed, out_dir, write_doc, silent):
    """The fundamental matrix on the 8 real 3-D pairs of ../shared/data/ef, both orders:
    scalematch (model fundamental; its default plane map recorded) and SIFT + USAC_MAGSAC,
    scored by the mean symmetric epipolar distance of the clicked points.

    \b
    Example:
      scalematch lab ef-pairs --out-dir bench-out/ef
      scalematch lab ef-pairs --pairs booksh,zoom --methods scalematch,sift-magsac
    """
    import datetime as _dt
    import sys

    folder = require_shared(shared, EF_SUBDIR) / EF_SUBDIR
    names = [n.strip() for n in pairs.split(",") if n.strip()] or pair_names(folder)
    known = pair_names(folder)
    for n in names:
        if n not in known:
            raise click.BadParameter(f"unknown pair {n!r}; one of {', '.join(known)}",
                                     param_hint="--pairs")
    wanted = [m.strip() for m in methods.split(",") if m.strip()]
    for m in wanted:
        if m not in METHODS:
            raise click.BadParameter(f"unknown method {m!r}; one of {', '.join(METHODS)}",
                                     param_hint="--methods")
    log = (lambda s: None) if silent else (lambda s: click.echo(s, err=True))
    meta = {"date": _dt.datetime.now().strftime("%Y-%m-%d %H:%M"), "seed": seed,
            "machine": f"{platform.machine()}, {os.cpu_count()} cores",
            "load": " ".join(f"{v:.1f}" for v in os.getloadavg()), "opencv": cv2.__version__,
            "command": ("scalematch lab ef-pairs " + " ".join(sys.argv[3:])).strip()}
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in names:
        pair = load_pair(folder, name)
        rows += run_orders(pair, wanted, lambda order, run: row_of(pair, order, run), seed, log)
        (out_dir / "rows.json").write_text(json.dumps(rows, indent=1, default=str))
    (out_dir / "meta.json").write_text(json.dumps(meta))
    text = markdown(rows, meta)
    (out_dir / "ef-pairs.md").write_text(text)
    click.echo(text)
    if write_doc is not None:
        from .realpairs import write_section

        write_section(write_doc, text, "ef-pairs", "scalematch lab ef-pairs")
        log(f"wrote {write_doc}")
