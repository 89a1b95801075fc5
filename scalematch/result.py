"""The answer of a match: a frozen dataclass with the per-scale table (paper Table 1).

Conventions, kept everywhere: pixels in OpenCV's convention (x right, y down, pixel centres at
integer coordinates); ``transform`` maps a *high-resolution* pixel to a *low-resolution* pixel
(2x3 for similarity and affine, 3x3 for homography; for the fundamental matrix, the 3x3 F with
``x_low^T F x_high = 0``); angles in degrees in what users see.
"""

from __future__ import annotations

import enum
import math
from dataclasses import asdict, dataclass, field, fields, is_dataclass
from typing import Any, Dict, Mapping, Optional, Sequence, Tuple

import numpy as np

from .stages.estimator import model_of


class Direction(str, enum.Enum):
    """Which of the two images given is the coarser one: the one way the order is told.

    A ``str`` enum, so it compares equal to its value and is written to JSON as that value.

    >>> Direction.SWAPPED == "swapped", Direction.GIVEN.other
    (True, <Direction.SWAPPED: 'swapped'>)
    """

    GIVEN = "given"  #: the first image given is the coarser one (the ``low`` argument)
    SWAPPED = "swapped"  #: the second image given is the coarser one

    @property
    def other(self) -> "Direction":
        return Direction.SWAPPED if self is Direction.GIVEN else Direction.GIVEN

    def coarser_finer(self, first, second):
        """(coarser, finer) of the two images given (first, second) in this direction."""
        return (first, second) if self is Direction.GIVEN else (second, first)

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class NoDataSeen:
    """What one image showed of no-data (:mod:`scalematch.stages.nodata`): JSON ``low.nodata``
    and ``high.nodata``."""

    value: float = math.nan  #: the grey level taken as no-data (NaN, null in the JSON: none)
    share: float = 0.0  #: share of the image taken as no-data, 0..1


@dataclass(frozen=True)
class Evidence:
    """The figures behind the decision (JSON ``evidence``); NaN where a figure was not reached.

    Made only by :func:`build_evidence`, in the answer module alone
    (:func:`scalematch.answer.evidence_of`: the figures the decision of the search shown
    reached, ``Decision.figures``, the final transform's pixel tests, the search's own figures
    and the working size's).
    """

    inliers: int = 0  #: distinct inliers of the best transform
    candidates: int = 0  #: distinct candidate matches at its scale
    log10_nfa: float = math.inf  #: log10 expected number of chance transforms as good (a contrario)
    chance_p: float = math.nan  #: chance that one random candidate fits the transform
    implied_ratio: float = math.nan  #: the ratio the transform implies at the winning scale
    footprint_area_px: float = math.nan  #: area of the high image's footprint, low px^2
    footprint_inside: float = math.nan  #: fraction of the footprint inside the low image
    agreeing_scales: int = 0  #: other scales whose transform agrees with the winner's
    #: the second look (``stages.secondlook.look_again``), for a best transform of 3+ inliers:
    grown_inliers: int = 0  #: distinct inliers after guided growth
    grown_chance: float = math.nan  #: guided matches to expect by chance
    pixel_ncc: float = math.nan  #: ZNCC of the pixels under the grown map
    pixel_margin: float = math.nan  #: how much better than the nearby wrong placements
    pixel_z: float = math.nan  #: the same in standard deviations of the nearby placements
    #: the same by windows (``stages.pixelcheck.near_windows``), measured only when the margin
    #: above falls short of ``decision.few_min_margin`` at log10 NFA ``few_max_log_nfa`` or
    #: below: windows compared, the share that agrees at the grown map, the highest share at a
    #: nearby placement
    pixel_windows: int = 0
    pixel_windows_agreeing: float = math.nan
    pixel_windows_nearby: float = math.nan
    #: a transform about to be accepted, against every other placement (``uniqueness``):
    unique_claimed: float = math.nan  #: ZNCC of the finer image at the claimed placement
    unique_elsewhere: float = math.nan  #: the best ZNCC anywhere half a footprint away
    unique_ratio: float = math.nan  #: misfit elsewhere over misfit at the claim
    #: the same by windows (``stages.uniqueness.window_agreement``), measured only when the
    #: ratio above refuses: windows compared, the share that agrees at the claim, the highest
    #: share anywhere else
    unique_windows: int = 0
    windows_agreeing: float = math.nan
    windows_elsewhere: float = math.nan
    #: the pixel check of the final (refit) transform, as ``pixel_ncc`` / ``pixel_margin`` are
    #: of the search's: the map reported, an affine map or a homography where the view is tilted
    final_ncc: float = math.nan
    final_margin: float = math.nan
    #: the same by windows (``stages.pixelcheck.near_windows``), measured only when the margin
    #: above refuses: windows compared, the share that agrees at the claim, the highest share
    #: at a nearby placement
    near_windows: int = 0
    near_windows_agreeing: float = math.nan
    near_windows_nearby: float = math.nan
    #: what judged the match unique: "geometry" (log10 NFA beyond
    #: ``decision.max_log_nfa_geometry``, no second transform) or "pixels" (the tests above)
    judged_by: str = ""
    #: the strongest other transform among the winner's candidates
    #: (``stages.decision.second_transform``): a repeated structure shows as one of the same
    #: scale and angle, shifted, with comparable support
    second_inliers: int = 0
    second_log10_nfa: float = math.inf
    second_gap_px: float = math.nan  #: its mean distance from the winner's map, px
    #: candidates off the winner's plane that an epipolar geometry explains
    #: (``stages.rivals.off_plane``), and whether they show parallax: a 3-D scene, the
    #: transform that of its dominant plane (``--model fundamental`` gives the epipolar geometry)
    parallax_points: int = 0
    parallax: bool = False
    #: ``--model fundamental``: the log10 NFA of the epipolar geometry's inliers off the
    #: dominant plane among the candidates off it (``stages.finalchecks.plane_parallax``); at
    #: most ``max_log_nfa``, the geometry shows parallax by itself (nan: not measured)
    parallax_log10_nfa: float = math.nan
    #: ``--model fundamental``: of those inliers off the plane, the ones whose own match fits
    #: the pixels better than the plane's prediction (``stages.pixelcheck.matches_beat_plane``),
    #: and their log10 NFA with the plane given, the epipole alone to fix
    #: (``stages.finalchecks.plane_parallax``); where the plane map of the pair passes the
    #: decision and this is at most ``max_log_nfa``, the epipolar geometry answers
    #: (``answer.without_parallax``; nan: not measured, as for a matrix with parallax of its
    #: own)
    parallax_vouched_points: int = 0
    epipole_log10_nfa: float = math.nan
    #: ``--model fundamental`` with no parallax: the distinct inliers of the plane map that
    #: answers instead, or establishes the plane for the matrix (``answer.without_parallax``;
    #: 0: no plane map passed)
    plane_inliers: int = 0
    #: ``--model fundamental`` with no parallax, where the pixels over the plane map's whole
    #: footprint alone refused it: its windows near its own inliers
    #: (``answer.plane_near_its_inliers``): windows compared, the share that agrees at the
    #: map, the highest share at a nearby placement; where they agree, the plane is established
    #: for the matrix (``plane_inliers`` then counts its inliers) but does not answer itself
    plane_windows: int = 0
    plane_windows_agreeing: float = math.nan
    plane_windows_nearby: float = math.nan
    #: how firmly the answer's inliers pin its map (``stages.pinning.expected_error``): the
    #: error they leave it free to make, the mean over the finer image's 21x21 grid of each
    #: point's RMS position error, coarser px
    pin_px: float = math.nan
    #: the model fitted first that is not claimed because its inliers left it free to err by
    #: more than ``pin.tolerance_px`` ("" when the answer is the model fitted), and its expected
    #: grid error, coarser px (``stages.refit.pinned_model``)
    unpinned_model: str = ""
    unpinned_px: float = math.nan
    searches: int = 0  #: searches made (one per direction and view probed)
    search_order: Direction = Direction.GIVEN  #: the direction of the search shown
    view_tilt: float = 1.0  #: tilt of the simulated view of the search shown (1: the image)
    view_longitude_deg: float = 0.0  #: its longitude, degrees
    view_of: str = "finer"  #: which image that view is of: "finer" or "coarser"
    probe_score: float = math.nan  #: the probe's best score in the search shown
    probe_best: float = math.nan  #: the best probe score of every search made
    steps_run: int = 0  #: steps of the search plan run (``MatchResult.search``)
    steps_planned: int = 0  #: steps in the plan
    stopped: str = ""  #: why the search stopped (``plan.STOP_REASONS``)
    low_working_factor: float = 1.0  #: the low image was matched shrunk by this factor
    high_working_factor: float = 1.0  #: the high image was matched shrunk by this factor


def figure(figures: Mapping[str, Any], name: str) -> Any:
    """The figure ``name`` of ``figures`` (by :class:`Evidence`'s names), or Evidence's default
    where it was not reached (NaN, inf or 0).

    >>> figure({"inliers": 12}, "inliers"), figure({}, "log10_nfa")
    (12, inf)
    """
    return figures[name] if name in figures else EVIDENCE_DEFAULTS[name]


def build_evidence(*parts: Mapping[str, Any]) -> Evidence:
    """The one way an :class:`Evidence` is made: the figures of ``parts``, in order, a later
    part's over an earlier one's; a figure no part gives keeps its default (NaN or 0: not
    reached). The decision's tests, the pixel tests of the final map, the search and the
    working size each give their figures (``stages.decision.decide``,
    ``answer.evidence_of``).

    >>> e = build_evidence({"inliers": 12, "log10_nfa": -20.0}, {"log10_nfa": -21.5})
    >>> e.inliers, e.log10_nfa, math.isnan(e.final_ncc)
    (12, -21.5, True)
    """
    figures: Dict[str, Any] = {}
    for part in parts:
        figures.update(part)
    return Evidence(**figures)


#: Each figure of an :class:`Evidence` and its value where it was not reached (:func:`figure`)
EVIDENCE_DEFAULTS: Dict[str, Any] = {f.name: f.default for f in fields(Evidence)}


@dataclass(frozen=True)
class StepRecord:
    """What one step of the search plan did (JSON ``search``, one object per step run)."""

    direction: Direction  #: which image was taken as the coarser one (the views: the first)
    view_pass: int  #: 0: the finer image itself; k: the k-th pass of tilted views of both images
    #: view pairs searched: 1 for the finer image itself; for the views, every pair of the
    #: pooled vote (each image's views against the other image, in each direction)
    views: int
    full: int  #: view pairs matched in full (the probe's or the vote's choice)
    #: the best probe score (the image itself), or the best cell's votes (the views)
    probe_best: float
    matched: bool  #: a reliable match was found in this step
    side: str = "finer"  #: whose views: "finer" (the image itself) or "both" (``Step.side``)

    @property
    def name(self) -> str:
        """``given pass 0``: the key of the step's time in ``MatchResult.timings`` (``views
        pass 1`` for the first pass of views)."""
        return f"views pass {self.view_pass}" if self.view_pass else f"{self.direction} pass 0"


@dataclass(frozen=True)
class ScaleRow:
    """One row of the per-scale table (the paper's Table 1)."""

    s: float  #: scale of the high-resolution image
    ratio: float  #: resolution ratio implied by this scale's transform (nan when none)
    points: int  #: interest points in the high-resolution image at s
    #: candidate (descriptor) matches, as distinct point pairs (a point described at two
    #: orientations is one)
    initial: int
    kept: int  #: distinct candidate pairs surviving the local geometric constraints
    inliers: int  #: inliers of the robust estimate (0 when none)
    outlier_pct: float  #: 100 * (1 - inliers / initial) (100 when no initial match)
    rotation_deg: float = float("nan")  #: rotation implied by this scale's transform
    skipped: bool = False  #: True when the scale was skipped as hopeless from its initial matches


@dataclass(frozen=True)
class Rejected:
    """The best candidate of a "no" (JSON ``rejected``): what was found and which test refused
    it, so that a user sees both. In a match's conventions: ``transform`` maps the finer
    image's pixels to the coarser one's, ``order`` says which image given is the coarser."""

    transform: np.ndarray = field(repr=False)  #: 2x3 or 3x3, finer px -> coarser px
    model: str  #: similarity | affine | homography
    inliers: np.ndarray = field(repr=False)  #: (N, 4) x_finer, y_finer, x_coarser, y_coarser
    log10_nfa: float  #: how far beyond chance its inliers are (a contrario)
    #: which test refused it (``stages.acontrario.TESTS``: "chance", "uniqueness", ...)
    test: str
    #: that test's figures and limits (``stages.acontrario.figures``)
    figures: Dict[str, Any] = field(default_factory=dict)
    order: Direction = Direction.GIVEN  #: GIVEN: the first image given is the coarser one

    @property
    def n_inliers(self) -> int:
        return int(np.asarray(self.inliers).reshape(-1, 4).shape[0])

    def to_dict(self) -> Dict[str, Any]:
        """Plain JSON types: the transform, model, order, inlier count and pairs, log10 NFA,
        the test and its figures."""
        return {"transform": to_jsonable(np.asarray(self.transform, np.float64)),
                "model": self.model, "order": str(self.order), "n_inliers": self.n_inliers,
                "matches": to_jsonable(np.round(np.asarray(self.inliers, np.float64)
                                                .reshape(-1, 4), 3)),
                "log10_nfa": to_jsonable(float(self.log10_nfa)), "test": self.test,
                "figures": to_jsonable(self.figures)}


@dataclass(frozen=True)
class MatchResult:
    """Everything a match produced; ``matched`` False means "no reliable match" (see ``reason``)."""

    matched: bool
    model: str  #: similarity | affine | homography | fundamental
    reason: str = ""  #: why not matched ("" when matched)
    #: finer px -> coarser px (None when not matched): the second image given to the first,
    #: or with ``order`` "swapped" the first to the second
    transform: Optional[np.ndarray] = field(default=None, repr=False)
    #: 1/h: high-res pixels per low-res pixel (a homography's: where its inliers are,
    #: :func:`scalematch.geometry.answer_parts`)
    resolution_ratio: float = math.nan
    rotation_deg: float = math.nan  #: atan2(T[1,0], T[0,0]) in degrees (a homography's: there)
    translation: Tuple[float, float] = (math.nan, math.nan)  #: (T[0,2], T[1,2])
    best_scale: float = math.nan  #: the winning scale s (nan when none)
    #: (N, 4) x_high, y_high, x_low, y_low
    inliers: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)), repr=False)
    scales: Tuple[ScaleRow, ...] = field(default=(), repr=False)
    timings: Dict[str, float] = field(default_factory=dict, repr=False)  #: stage -> seconds
    config: Any = field(default=None, repr=False)  #: the Config used
    evidence: Evidence = field(default_factory=Evidence, repr=False)  #: decision figures
    #: GIVEN: the first image given is the coarser one; SWAPPED: the second is (the
    #: transform and the inliers always go from the finer image to the coarser one)
    order: Direction = Direction.GIVEN
    search: Tuple[StepRecord, ...] = field(default=(), repr=False)  #: the steps run, in order
    #: provenance of the paper mode: which Lambda was used ("packaged" or the resolved path,
    #: with the first 12 hex digits of the file's SHA-256); "" in the default mode
    covariance_used: str = ""
    #: a "no": its best candidate and the test that refused it (None when matched, or when no
    #: transform was found)
    rejected: Optional[Rejected] = field(default=None, repr=False)
    #: what the first and the second image given showed of no-data
    nodata: Tuple[NoDataSeen, NoDataSeen] = (NoDataSeen(), NoDataSeen())

    def __post_init__(self) -> None:
        object.__setattr__(self, "order", Direction(self.order))
        # frozen means frozen: the arrays are read-only copies, so a result cannot be edited
        # in place (a caller's own array stays writable)
        for name in ("transform", "inliers"):
            value = getattr(self, name)
            if value is not None:
                value = np.array(value)
                value.setflags(write=False)
                object.__setattr__(self, name, value)

    @property
    def n_inliers(self) -> int:
        return int(self.inliers.shape[0])

    @property
    def seconds(self) -> float:
        return float(self.timings.get("total", sum(self.timings.values())))

    def to_dict(self, low_path: Optional[str] = None, high_path: Optional[str] = None,
                low_shape: Optional[Sequence[int]] = None,
                high_shape: Optional[Sequence[int]] = None,
                warnings: Tuple[str, str] = ("", "")) -> Dict[str, Any]:
        """The documented JSON object of this match (README.md, "Output"; docs/GUIDE.md, "JSON"):
        plain types only.

        ``low``/``high``: the coarser and the finer image as found (exchanged when swapped).

        Parameters
        ----------
        low_path, high_path : str, optional
            The inputs as the user named them, in the order given (recorded, not read); None
            (arrays matched in Python) writes null.
        low_shape, high_shape : (H, W) tuples, optional
            The images' sizes in px, after EXIF orientation; None writes null width and height.
        warnings : (str, str)
            What reading the first and the second image given warned of (``Decoded.warning``).

        >>> r = MatchResult(matched=False, reason="too few inliers", model="similarity",
        ...                 transform=None, resolution_ratio=float("nan"),
        ...                 rotation_deg=float("nan"), translation=(float("nan"),) * 2,
        ...                 best_scale=2.0, inliers=np.zeros((0, 4)), scales=(),
        ...                 timings={"total": 0.5}, config={})
        >>> d = r.to_dict("a.png", "b.png", (120, 160), (480, 640))
        >>> d["matched"], d["reason"], d["resolution_ratio"], d["high"]["width"]
        (False, 'too few inliers', None, 640)
        >>> r.to_dict()["low"]  # arrays matched in Python: no path or size to record
        {'path': None, 'width': None, 'height': None, 'nodata': {'value': None, 'share': 0.0}, 'warning': None}
        """
        from . import __version__

        low, high = self._image_records((low_path, high_path), (low_shape, high_shape), warnings)
        t = self.transform
        return {
            "matched": bool(self.matched),
            "reason": None if self.matched else (self.reason or "no reliable match"),
            "model": self.model,
            "order": str(self.order),
            "transform": None if t is None else to_jsonable(np.asarray(t, dtype=np.float64)),
            "resolution_ratio": to_jsonable(float(self.resolution_ratio)),
            "rotation_deg": to_jsonable(float(self.rotation_deg)),
            "translation": to_jsonable(list(self.translation)),
            "epipoles": self._epipoles(),
            "best_scale": to_jsonable(float(self.best_scale)),
            "n_inliers": self.n_inliers,
            "inliers": self.n_inliers,  # the count under its old name, until version 1.0
            "matches": to_jsonable(np.round(np.asarray(self.inliers, np.float64).reshape(-1, 4), 3)),
            "scales": [to_jsonable(row) for row in self.scales],
            "seconds": round(self.seconds, 3),
            "timings": to_jsonable({k: round(float(v), 3) for k, v in self.timings.items()}),
            "evidence": to_jsonable(self.evidence),
            "search": [to_jsonable(step) for step in self.search],
            "config": to_jsonable(self.config),
            "covariance_used": self.covariance_used or None,
            "rejected": None if self.rejected is None else self.rejected.to_dict(),
            "version": __version__,
            "low": low, "high": high,
        }

    def _image_records(self, paths: Tuple[Optional[str], Optional[str]],
                       shapes: Tuple[Optional[Sequence[int]], Optional[Sequence[int]]],
                       warnings: Tuple[str, str]) -> Tuple[Dict[str, Any], Dict[str, Any]]:
        """The "low" and "high" records of the images given (first, second): the coarser
        image's first, as ``order`` says."""
        first, second = (_image_record(path, shape, nodata, warning) for path, shape, nodata,
                         warning in zip(paths, shapes, self.nodata, warnings))
        return (second, first) if self.order == Direction.SWAPPED else (first, second)

    def _epipoles(self) -> Optional[Dict[str, list]]:
        """A matched fundamental matrix's epipoles by image, "low" and "high"
        (:func:`scalematch.geometry.epipoles`: ``[x, y, 1]`` px, or ``[dx, dy, 0]`` at
        infinity); None for other answers."""
        found = model_of(self.model).epipoles(self.transform) \
            if self.matched and self.transform is not None else None
        if found is None:
            return None
        finer, coarser = (np.round(e, 3).tolist() for e in found)
        low, high = (finer, coarser) if self.order == Direction.SWAPPED else (coarser, finer)
        return {"low": low, "high": high}

    def to_json(self, low_path: Optional[str] = None, high_path: Optional[str] = None,
                low_shape: Optional[Sequence[int]] = None,
                high_shape: Optional[Sequence[int]] = None, indent: Optional[int] = 2,
                warnings: Tuple[str, str] = ("", "")) -> str:
        """The text of ``scalematch LOW HIGH --json FILE``: :meth:`to_dict` as JSON, ending in a
        newline (``indent=None``: one line, as ``batch`` writes)."""
        return dumps(self.to_dict(low_path, high_path, low_shape, high_shape, warnings),
                     indent) + "\n"


def _image_record(path: Optional[str], shape: Optional[Sequence[int]],
                  nodata: NoDataSeen = NoDataSeen(), warning: str = "") -> Dict[str, Any]:
    """An image's "low"/"high" object: its path and size, null where not known, what it
    showed of no-data, and what its reading warned of (null: nothing)."""
    return {"path": None if path is None else str(path),
            "width": None if shape is None else int(shape[1]),
            "height": None if shape is None else int(shape[0]),
            "nodata": {"value": to_jsonable(float(nodata.value)),
                       "share": round(float(nodata.share), 4)},
            "warning": warning or None}


def error_record(low_path: str, high_path: str, error: str, kind: str, config: Any,
                 seconds: float = 0.0) -> Dict[str, Any]:
    """The JSON of a pair that could not be matched (docs/GUIDE.md, "JSON"), as a batch line
    and ``scalematch LOW HIGH --json`` write it: ``kind`` "input" (the pair's files or values)
    or "internal" (an unexpected error, whose message then starts "internal error")."""
    from . import __version__

    return {"low": {"path": str(low_path)}, "high": {"path": str(high_path)}, "matched": False,
            "error": error, "error_kind": kind, "seconds": round(seconds, 3),
            "config": to_jsonable(config), "version": __version__}


def to_jsonable(obj: Any) -> Any:
    """Dataclasses, numpy arrays and scalars -> plain JSON types (nan -> None)."""
    if is_dataclass(obj) and not isinstance(obj, type):
        return {k: to_jsonable(v) for k, v in asdict(obj).items()}
    if isinstance(obj, enum.Enum):
        return to_jsonable(obj.value)
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        f = float(obj)
        return None if math.isnan(f) or math.isinf(f) else f
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    return obj


def dumps(obj: Dict[str, Any], indent: Optional[int] = None) -> str:
    """JSON text; objects json cannot write (paths, numpy scalars left over) become strings."""
    import json  # for --json and the batch only

    return json.dumps(to_jsonable(obj), indent=indent, default=str, allow_nan=False)
