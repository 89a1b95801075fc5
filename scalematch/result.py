"""The answer of a match: a frozen dataclass with the per-scale table (paper Table 1).

Conventions, kept everywhere: pixels in OpenCV's convention (x right, y down, pixel centres at
integer coordinates); ``transform`` maps a *high-resolution* pixel to a *low-resolution* pixel
(2x3 for similarity and affine, 3x3 for homography; for the fundamental matrix, the 3x3 F with
``x_low^T F x_high = 0``); angles in degrees in what users see.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, is_dataclass
from typing import Any, Dict, Optional, Tuple

import numpy as np


@dataclass(frozen=True)
class ScaleRow:
    """One row of the per-scale table (the paper's Table 1)."""

    s: float  #: scale of the high-resolution image
    ratio: float  #: resolution ratio implied by this scale's transform (nan when none)
    points: int  #: interest points in the high-resolution image at s
    initial: int  #: candidate (descriptor) matches
    kept: int  #: candidates surviving the local geometric constraints
    inliers: int  #: inliers of the robust estimate (0 when none)
    outlier_pct: float  #: 100 * (1 - inliers / initial) (100 when no initial match)
    rotation_deg: float = float("nan")  #: rotation implied by this scale's transform
    skipped: bool = False  #: True when the scale was skipped as hopeless from its initial matches


@dataclass(frozen=True)
class MatchResult:
    """Everything a match produced; ``matched`` False means "no reliable match" (see ``reason``)."""

    matched: bool
    reason: str  #: why not matched ("" when matched)
    model: str  #: similarity | affine | homography | fundamental
    transform: Optional[np.ndarray] = field(repr=False)  #: high px -> low px (None when not matched)
    resolution_ratio: float  #: 1/h: high-res pixels per low-res pixel (nan when not matched)
    rotation_deg: float  #: atan2(T[1,0], T[0,0]) in degrees (nan when not matched)
    translation: Tuple[float, float]  #: (T[0,2], T[1,2]) (nan when not matched)
    best_scale: float  #: the winning scale s (nan when none)
    inliers: np.ndarray = field(repr=False)  #: (N, 4) x_high, y_high, x_low, y_low
    scales: Tuple[ScaleRow, ...] = field(repr=False)
    timings: Dict[str, float] = field(repr=False)  #: stage name -> seconds
    config: Any = field(repr=False)  #: the Config used
    evidence: Dict[str, float] = field(default_factory=dict, repr=False)  #: decision figures
    #: "given": the first image given is the coarser one; "swapped": the second is (the
    #: transform and the inliers always go from the finer image to the coarser one)
    order: str = "given"

    def __post_init__(self) -> None:
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


def to_jsonable(obj: Any) -> Any:
    """Dataclasses, numpy arrays and scalars -> plain JSON types (nan -> None)."""
    if is_dataclass(obj) and not isinstance(obj, type):
        return {k: to_jsonable(v) for k, v in asdict(obj).items()}
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
