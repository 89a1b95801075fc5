"""The answer of a match: a frozen dataclass with the per-scale table (paper Table 1).

Conventions, kept everywhere: pixels in OpenCV's convention (x right, y down, pixel centres at
integer coordinates); ``transform`` maps a *high-resolution* pixel to a *low-resolution* pixel
(2x3 for similarity and affine, 3x3 for homography; for the fundamental matrix, the 3x3 F with
``x_low^T F x_high = 0``); angles in degrees in what users see.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, is_dataclass
from typing import Any, Dict, Optional, Sequence, Tuple

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

    def to_dict(self, low_path: str, high_path: str, low_shape: Sequence[int],
                high_shape: Sequence[int]) -> Dict[str, Any]:
        """The documented JSON object of this match (README.md, "## Output"): plain types only.

        ``low``/``high`` describe the coarser and the finer image as found: with ``order``
        "swapped" the first image given is the finer one, and they are exchanged.

        Parameters
        ----------
        low_path, high_path : str
            The inputs as the user named them, in the order given (recorded, not read).
        low_shape, high_shape : (H, W) tuples
            The images' sizes in px, after EXIF orientation.

        >>> r = MatchResult(matched=False, reason="too few inliers", model="similarity",
        ...                 transform=None, resolution_ratio=float("nan"),
        ...                 rotation_deg=float("nan"), translation=(float("nan"),) * 2,
        ...                 best_scale=2.0, inliers=np.zeros((0, 4)), scales=(),
        ...                 timings={"total": 0.5}, config={})
        >>> d = r.to_dict("a.png", "b.png", (120, 160), (480, 640))
        >>> d["matched"], d["reason"], d["resolution_ratio"], d["high"]
        (False, 'too few inliers', None, {'path': 'b.png', 'width': 640, 'height': 480})
        """
        from . import __version__

        if self.order == "swapped":
            low_path, high_path, low_shape, high_shape = high_path, low_path, high_shape, low_shape
        t = self.transform
        return {
            "matched": bool(self.matched),
            "reason": None if self.matched else (self.reason or "no reliable match"),
            "model": self.model,
            "order": self.order,
            "transform": None if t is None else to_jsonable(np.asarray(t, dtype=np.float64)),
            "resolution_ratio": to_jsonable(float(self.resolution_ratio)),
            "rotation_deg": to_jsonable(float(self.rotation_deg)),
            "translation": to_jsonable(list(self.translation)),
            "best_scale": to_jsonable(float(self.best_scale)),
            "n_inliers": self.n_inliers,
            "inliers": self.n_inliers,  # the count under its old name, until version 1.0
            "matches": to_jsonable(np.round(np.asarray(self.inliers, np.float64).reshape(-1, 4), 3)),
            "scales": [to_jsonable(row) for row in self.scales],
            "seconds": round(self.seconds, 3),
            "timings": to_jsonable({k: round(float(v), 3) for k, v in self.timings.items()}),
            "evidence": to_jsonable(self.evidence),
            "config": to_jsonable(self.config),
            "version": __version__,
            "low": {"path": str(low_path), "width": int(low_shape[1]), "height": int(low_shape[0])},
            "high": {"path": str(high_path), "width": int(high_shape[1]),
                     "height": int(high_shape[0])},
        }

    def to_json(self, low_path: str, high_path: str, low_shape: Sequence[int],
                high_shape: Sequence[int], indent: Optional[int] = 2) -> str:
        """The text of ``scalematch LOW HIGH --json FILE``: :meth:`to_dict` as JSON, ending in a
        newline (``indent=None``: one line, as ``batch`` writes)."""
        return dumps(self.to_dict(low_path, high_path, low_shape, high_shape), indent) + "\n"


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


def dumps(obj: Dict[str, Any], indent: Optional[int] = None) -> str:
    """JSON text; objects json cannot write (paths, numpy scalars left over) become strings."""
    return json.dumps(to_jsonable(obj), indent=indent, default=str, allow_nan=False)
