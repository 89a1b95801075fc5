"""One configuration object for a whole match, with every tunable number named and sourced.

Stage parameters live in small frozen dataclasses next to the stage that uses them; ``Config``
gathers them and is recorded with every result (``MatchResult.config``, the JSON ``config``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Optional, Tuple

from .stages.constraints import OrientationParams, SemiLocalParams
from .stages.decision import DecisionParams
from .stages.descriptors import GradientParams, JetParams
from .stages.detector import HarrisParams, PAPER_SCALES
from .stages.estimator import RansacParams
from .stages.matcher import MatcherParams
from .stages.views import ViewParams

#: Models the robust estimator can fit (paper section 5 and "Further examples").
MODELS = ("similarity", "affine", "homography", "fundamental")
#: "default": the improved pipeline; "paper": jets + Mahalanobis + semi-local constraints.
MODES = ("default", "paper")
#: "auto": find which image is the finer one (the given order first, then the other);
#: "given": the first image is the coarser one, as in version 0.1.
ORDERS = ("auto", "given")


def geometric_scales(lo: float, hi: float, steps_per_octave: int) -> Tuple[float, ...]:
    """Scales lo .. hi spaced by 2^(1/steps_per_octave), rounded to 3 decimals."""
    out = []
    k = 0
    while True:
        s = lo * 2.0 ** (k / steps_per_octave)
        if s > hi * (1 + 1e-9):
            break
        out.append(round(s, 3))
        k += 1
    return tuple(out)


@dataclass(frozen=True)
class ProbeParams:
    """Skipping hopeless scales from the initial matches of their strongest points (paper 5)."""

    enabled: bool = True  #: False runs the full matching at every scale
    #: strongest points per scale used to score it (100 and 150 measured the same success on
    #: the 38 photos at ratios 8 and 10; 100 is 16 % faster)
    points: int = 100
    keep: int = 3  #: best-scoring scales kept, each with its two neighbours
    #: RANSAC iterations of the probe's quick fit: 500 draws find a 2-point sample of inliers
    #: with 99.9 % confidence down to an inlier fraction of 12 %
    ransac_iters: int = 500


@dataclass(frozen=True)
class Config:
    """Everything a match depends on. ``Config()`` is the default; ``Config.paper()`` the paper."""

    mode: str = "default"  #: "default" or "paper" (see MODES)
    model: str = "similarity"  #: similarity | affine | homography | fundamental
    #: scales s of the high-resolution image to try: 1 to 12.7 by third octaves (12 scales;
    #: the paper: 1..8 in unit steps, PAPER_SCALES). Ratios up to 10 need scales past 8; a
    #: scale within 2^(1/6) = 12 % of the true ratio matches well. Quarter octaves (15 scales)
    #: measured 1 more success in 38 at ratio 10 for 12 % more time (docs/ABLATION.md).
    scales: Tuple[float, ...] = geometric_scales(1.0, 12.7, 3)
    seed: int = 0  #: the one seed for all randomness (RANSAC)
    harris: HarrisParams = field(default_factory=HarrisParams)  #: the high image, every scale
    #: the low image, at s = 1 only: the same detector; more points allowed, since the high
    #: image's footprint may be a small part of it
    harris_low: HarrisParams = field(default_factory=lambda: HarrisParams(max_points=12000))
    gradients: GradientParams = field(default_factory=GradientParams)  #: default descriptor
    jets: JetParams = field(default_factory=JetParams)  #: paper descriptor
    covariance_path: Optional[str] = None  #: Lambda for the jets (None: data/jet_covariance.json)
    matcher: MatcherParams = field(default_factory=MatcherParams)
    orientation: OrientationParams = field(default_factory=OrientationParams)  #: default mode
    semi_local: SemiLocalParams = field(default_factory=SemiLocalParams)  #: paper mode
    ransac: RansacParams = field(default_factory=RansacParams)
    probe: ProbeParams = field(default_factory=ProbeParams)
    decision: DecisionParams = field(default_factory=DecisionParams)
    order: str = "auto"  #: see ORDERS
    #: simulated tilted views of the finer image, tried when the plain search finds nothing
    views: ViewParams = field(default_factory=ViewParams)
    #: longest side, px, at which the low image is matched (None: its full size). A larger low
    #: image is shrunk to it (INTER_AREA) and the answer given in its own pixels
    #: (``scalematch.working``). The low detector keeps at most 12,000 points anyway; at 2048 px
    #: a 24 MP (6000x4000) low image becomes 2.8 MP: time and memory are bounded, and images up
    #: to 2048 px (the benchmark's 1024x768) are matched exactly as before.
    low_max_side: Optional[int] = 2048

    def __post_init__(self) -> None:
        if self.order not in ORDERS:
            raise ValueError(f"order must be one of {ORDERS}, got {self.order!r}")
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        if self.model not in MODELS:
            raise ValueError(f"model must be one of {MODELS}, got {self.model!r}")
        if self.low_max_side is not None and self.low_max_side < 64:
            raise ValueError(f"low_max_side must be None or at least 64 px, got {self.low_max_side}")
        if not self.scales or min(self.scales) < 1.0:
            raise ValueError("scales must be a non-empty list of values >= 1")

    @staticmethod
    def paper(**changes) -> "Config":
        """The paper's method as published: scales 1..8, jets, Mahalanobis, constraints."""
        base = Config(mode="paper", scales=PAPER_SCALES,
                      # the paper: Mahalanobis nearest neighbours, then the constraints decide
                      matcher=MatcherParams(selection="knn", k=3),
                      # "In practice we run the latter algorithm at all scales" (section 5)
                      probe=ProbeParams(enabled=False))
        return replace(base, **changes)
