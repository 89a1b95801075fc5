"""One configuration object for a whole match, with every tunable number named and sourced.

Stage parameters live in small frozen dataclasses next to the stage that uses them; ``Config``
gathers them and is recorded with every result (``MatchResult.config``, the JSON ``config``).
"""

from __future__ import annotations

from dataclasses import MISSING, dataclass, field, fields, replace
from typing import Any, Callable, ClassVar, Dict, Mapping, Optional, Tuple

from .checks import FACTOR, NON_NEGATIVE, Bounds, check_bounds, in_range, one_of
from .stages.constraints import OrientationParams, SemiLocalParams
from .stages.acontrario import DecisionParams
from .stages.descriptors import GradientParams, JetParams
from .stages.detector import HarrisParams, PAPER_SCALES
from .stages.estimator import MODELS as _MODEL_RECORDS, RansacParams
from .stages.guided import GuidedParams
from .stages.matcher import MatcherParams
from .stages.nodata import NoDataParams
from .stages.pinning import PinParams
from .stages.pixelcheck import PixelParams
from .stages.probe import ProbeParams
from .stages.refit import ModelCheckParams
from .stages.views import TILT4_PASSES, ViewParams
from .stages.vote import VoteParams

#: Names of the models the robust estimator can fit (the records: ``stages.estimator.MODELS``).
MODELS = tuple(_MODEL_RECORDS)
#: "default": the improved pipeline; "paper": jets + Mahalanobis + semi-local constraints.
MODES = ("default", "paper")
#: "auto": find which image is the finer one (the given order first, then the other);
#: "given": the first image is the coarser one, as in version 0.1.
ORDERS = ("auto", "given")


def geometric_scales(lo: float, hi: float, steps_per_octave: int) -> Tuple[float, ...]:
    """Scales lo .. hi spaced by 2^(1/steps_per_octave), rounded to 3 decimals.

    >>> geometric_scales(1.0, 4.0, 2)
    (1.0, 1.414, 2.0, 2.828, 4.0)
    """
    out = []
    k = 0
    while True:
        s = lo * 2.0 ** (k / steps_per_octave)
        if s > hi * (1 + 1e-9):
            break
        out.append(round(s, 3))
        k += 1
    return tuple(out)


#: Largest seed: OpenCV's random generator takes a C int (``cv2.setRNGSeed``), 2^31 - 1.
MAX_SEED = 2**31 - 1

#: Most scales a search takes: each scale is a level detected and probed in every view, so the
#: time and memory of a "no" grow with their number (15,001 scales held 3.7 GB and had written
#: nothing after a minute). 64 is five times the default's 13 third-octave scales and more than
#: quarter octaves over 1-64 (25) or half steps over 1-32 (63) need.
MAX_SCALES = 64

#: Smallest working size, px: below it the 24 px minimum side of a level (detector.MIN_SIDE_PX)
#: leaves a shrunk image only its first scales.
MIN_WORKING_SIDE_PX = 64


@dataclass(frozen=True)
class Config:
    """Everything a match depends on. ``Config()`` is the default; ``Config.paper()`` the paper.

    Frozen: change a copy with :func:`dataclasses.replace` or ``Config.preset(name, **changes)``.
    Its ``repr`` shows the fields that differ from the default (``Config()`` is the default);
    ``dataclasses.asdict(config)`` and a result's JSON ``config`` hold every value.

    >>> from dataclasses import replace
    >>> config = Config(seed=1)
    >>> config
    Config(seed=1)
    >>> len(config.scales), config.scales[:4], config.scales[-1], config.harris.sigma_tilde
    (13, (1.0, 1.26, 1.587, 2.0), 16.0, 2.0)
    >>> replace(config, harris=replace(config.harris, threshold=50.0)).harris.threshold
    50.0
    >>> Config(model="shear")
    Traceback (most recent call last):
    ...
    ValueError: model must be one of ('similarity', 'affine', 'homography', 'fundamental'), got 'shear'
    >>> Config(ransac=3)
    Traceback (most recent call last):
    ...
    TypeError: ransac must be a RansacParams, not int: change one of its values with replace(Config().ransac, NAME=VALUE) (--set ransac.NAME=VALUE)
    """

    mode: str = "default"  #: "default" or "paper" (see MODES)
    model: str = "similarity"  #: similarity | affine | homography | fundamental
    #: scales s of the high-resolution image to try: 1 to 16 by third octaves (13 scales;
    #: the paper: 1..8 in unit steps, PAPER_SCALES). Ratios up to 16 need scales past 8; a
    #: scale within 2^(1/6) = 12 % of the true ratio matches well. Quarter octaves measured 1
    #: more success in 38 at ratio 10 for 12 % more time (docs/results/ABLATION.md; docs/DESIGN.md,
    #: "Descriptors, matching and scales").
    #: A scale at which the finer image would span fewer than ``min_footprint_px`` coarser px
    #: is not searched (the search's reach follows the image sizes).
    scales: Tuple[float, ...] = geometric_scales(1.0, 16.0, 3)
    #: smallest footprint searched, coarser px along the finer image's longer side: a scale s
    #: is searched when that side / s is at least this: the largest ratio is the one whose
    #: footprint is still about 32 coarser pixels wide (the descriptor window is 16 px)
    min_footprint_px: float = 32.0
    seed: int = 0  #: the one seed for all randomness (RANSAC), 0 to MAX_SEED
    #: the finer image, every scale. The threshold follows the image's contrast (a 12-bit
    #: image stored as 0-4095 in 16 bits, or 32 grey levels, found no point at the absolute
    #: threshold; docs/design/DECISION.md, "Adaptive detection"); capped at 1, so it is only
    #: ever lowered (stages/detector.py). ``HarrisParams()`` is this detector, so
    #: ``scalematch.detect`` and ``match`` agree
    harris: HarrisParams = field(default_factory=HarrisParams)
    #: the coarser image, at s = 1 only: the same detector; more points allowed, since the
    #: finer image's footprint may be a small part of it
    harris_low: HarrisParams = field(default_factory=lambda: HarrisParams(max_points=12000))
    gradients: GradientParams = field(default_factory=GradientParams)  #: default descriptor
    jets: JetParams = field(default_factory=JetParams)  #: paper descriptor
    #: Lambda for the jets: a file written by `scalematch lab covariance` (None: the packaged
    #: scalematch/data/jet_covariance.json)
    covariance_path: Optional[str] = None
    matcher: MatcherParams = field(default_factory=MatcherParams)
    orientation: OrientationParams = field(default_factory=OrientationParams)  #: default mode
    semi_local: SemiLocalParams = field(default_factory=SemiLocalParams)  #: paper mode
    ransac: RansacParams = field(default_factory=RansacParams)
    probe: ProbeParams = field(default_factory=ProbeParams)
    decision: DecisionParams = field(default_factory=DecisionParams)
    #: the decision's second look at a hypothesis short of inliers: guided growth (the paper
    #: mode's jets carry no orientation, so there it never tests one)
    guided: GuidedParams = field(default_factory=GuidedParams)
    #: the pixel tests: the second look's check, the final transform's uniqueness and nearby
    #: placements, and the choice between several matched searches
    pixel: PixelParams = field(default_factory=PixelParams)
    order: str = "auto"  #: see ORDERS
    #: simulated tilted views of both images, tried when the plain search finds nothing
    views: ViewParams = field(default_factory=ViewParams)
    #: the pooled vote over the views' pairs: which are matched in full
    vote: VoteParams = field(default_factory=VoteParams)
    model_check: ModelCheckParams = field(default_factory=ModelCheckParams)
    #: an answer is claimed as its model only where its inliers pin it down: a map whose
    #: expected grid error exceeds ``pin.tolerance_px`` gives way to the next simpler model they
    #: pin (``stages.pinning``, ``stages.refit.pinned_model``)
    pin: PinParams = field(default_factory=PinParams)
    #: where an image shows no scene (a canvas's corners, a declared no-data value): kept out of
    #: detection and of the pixel tests (``stages.nodata``; ``--nodata``)
    nodata: NoDataParams = field(default_factory=NoDataParams)
    #: longest side, px, at which the low image is matched (None: its full size). A larger low
    #: image is shrunk to it (INTER_AREA) and the answer given in its own pixels
    #: (``scalematch.working``). The low detector keeps at most 12,000 points anyway; at 2048 px
    #: a 24 MP (6000x4000) low image becomes 2.8 MP: time and memory are bounded, and images up
    #: to 2048 px (the benchmark's 1024x768) are matched exactly as before.
    low_max_side: Optional[int] = 2048
    #: the same for the high image (None: its full size). Shrinking it can make it the coarser
    #: image, found then in the other order, so it applies only with ``order="auto"``. At 2048
    #: px a 24 MP high image was matched 2.1-5.9 times faster, 0.008-0.021 px from the truth
    #: at ratios 1.5 to 10 (full size: 0.008-0.041 px; docs/design/SPEED.md, "Working size").
    high_max_side: Optional[int] = 2048
    #: seconds after which no further step of the search plan is started (None: no limit).
    #: Checked between steps, never before the first (the given order's plain search), so a
    #: step under way finishes: a "no" comes sooner, but a pair only a later step would solve
    #: (the other order, tilted views) is then missed, and the answer depends on the machine's
    #: speed. docs/design/VIEWS.md, "The time budget", and docs/results/NULLS.md, "Mode budget-1s",
    #: measure what a 1 s budget saves on the null set and what it costs on tilted pairs
    time_budget_s: Optional[float] = None

    #: each number's range, checked when the configuration is made (``checks.check_bounds``;
    #: each parameter group declares its own)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "seed": Bounds(lo=0, hi=MAX_SEED, integer=True),
        # None: always full size
        "low_max_side": Bounds(lo=MIN_WORKING_SIDE_PX, integer=True, optional=True),
        "high_max_side": Bounds(lo=MIN_WORKING_SIDE_PX, integer=True, optional=True),
        "min_footprint_px": NON_NEGATIVE,
        "time_budget_s": Bounds(lo=0, lo_open=True, optional=True),
    }

    def __post_init__(self) -> None:
        for name, kind in _groups().items():  # Config(ransac=3) would fail only in match
            value = getattr(self, name)
            if not isinstance(value, kind):
                raise TypeError(f"{name} must be a {kind.__name__}, not {type(value).__name__}: "
                                f"change one of its values with replace(Config().{name}, "
                                f"NAME=VALUE) (--set {name}.NAME=VALUE)")
        if not isinstance(self.scales, (tuple, list)):
            raise TypeError(f"scales must be a tuple of scales >= 1, e.g. (1.0, 2.0, 4.0), not "
                            f"{type(self.scales).__name__}")
        one_of("", "order", self.order, ORDERS)
        one_of("", "mode", self.mode, MODES)
        one_of("", "model", self.model, MODELS)
        check_bounds("", self, self.BOUNDS)
        if len(self.scales) == 0:
            raise ValueError("scales must hold at least one scale (>= 1)")
        if len(self.scales) > MAX_SCALES:
            raise ValueError(f"scales: at most {MAX_SCALES} are searched, got {len(self.scales)}; "
                             f"a coarser step covers the same ratios (1-16 in third octaves "
                             f"is 13)")
        for s in self.scales:  # the high-resolution image is never enlarged
            in_range("", "scales", s, FACTOR)
        if self.mode == "paper" and self.guided.use_orientation:
            # the jets carry no orientation: guided growth compares descriptors alone, and the
            # configuration says so (it is recorded with every result)
            object.__setattr__(self, "guided", replace(self.guided, use_orientation=False))

    def __repr__(self) -> str:
        defaults = _defaults()
        changed = (f"{f.name}={getattr(self, f.name)!r}" for f in fields(self)
                   if getattr(self, f.name) != defaults[f.name])
        return f"Config({', '.join(changed)})"

    @staticmethod
    def paper(**changes) -> "Config":
        """The paper's method as published: scales 1..8, jets, Mahalanobis, constraints."""
        return Config.preset("paper", **changes)

    @staticmethod
    def preset(name: str, **changes) -> "Config":
        """The configuration called ``name`` in :data:`PRESETS`, with ``changes`` applied.

        >>> Config.preset("paper", seed=3).scales
        (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0)
        >>> Config.preset("default-no-probe").probe.enabled
        False
        >>> Config.preset("no-views").views.enabled  # as --no-views
        False
        """
        if name not in PRESETS:
            raise ValueError(f"unknown preset {name!r}; one of {', '.join(PRESETS)}")
        return replace(PRESETS[name](), **changes)


def _default_of(f: Any) -> Any:
    return f.default_factory() if f.default_factory is not MISSING else f.default


_DEFAULTS: Dict[str, Any] = {}


def _defaults() -> Dict[str, Any]:
    """Each field of ``Config`` and its default value (made once)."""
    if not _DEFAULTS:
        _DEFAULTS.update((f.name, _default_of(f)) for f in fields(Config))
    return _DEFAULTS


def _groups() -> Dict[str, type]:
    """The fields of ``Config`` that hold a group of parameters (a dataclass) and its class."""
    return {name: type(value) for name, value in _defaults().items()
            if hasattr(type(value), "__dataclass_fields__")}


def _paper() -> Config:
    return Config(mode="paper", scales=PAPER_SCALES,
                  # the paper: Mahalanobis nearest neighbours, then the constraints decide
                  matcher=MatcherParams(selection="knn", k=3),
                  # "In practice we run the latter algorithm at all scales" (section 5)
                  probe=ProbeParams(enabled=False),
                  # the jets carry no orientation to compare, nor to vote with: no views
                  guided=GuidedParams(use_orientation=False),
                  views=ViewParams(enabled=False),
                  # the paper's detector keeps what passes the threshold: no point budget
                  harris=HarrisParams(min_points=0),
                  harris_low=HarrisParams(max_points=12000, min_points=0))


#: Named configurations: the two modes, and the steps between them that the lab's ablation
#: measures (``scalematch lab bench --methods``; docs/results/ABLATION.md says what each step
#: bought). Each value makes its Config; ``Config.preset(name, **changes)`` is the way to get one.
PRESETS: Dict[str, Callable[[], Config]] = {
    "default": Config,
    "paper": _paper,
    # the paper's pipeline on the default's scales (1-16, third octaves)
    "paper-finer-scales": lambda: replace(_paper(), scales=Config().scales),
    # the default's descriptors and constraints on the paper's scales 1-8, every scale run
    "default-paper-scales": lambda: Config(scales=PAPER_SCALES, probe=ProbeParams(enabled=False)),
    # the default, every scale run (no probe)
    "default-no-probe": lambda: Config(probe=ProbeParams(enabled=False)),
    # the default on 15 scales 1-11.3 (quarter octaves)
    "default-quarter-octaves": lambda: Config(scales=geometric_scales(1.0, 12.0, 4)),
    # the default without its third pass of views (t = 6 and 8): tilts up to about 6 solved
    # (docs/design/VIEWS.md, "The third pass")
    "tilt-4": lambda: Config(views=ViewParams(passes=TILT4_PASSES)),
    # the default with a time budget of 1 s (docs/design/VIEWS.md, "The time budget"): no step
    # of the plan starts after 1 s, so a "no" costs about that much; docs/results/NULLS.md, "Mode
    # budget-1s", measures it on the null set (what a "no" then costs, and that no claim
    # appears)
    "budget-1s": lambda: Config(time_budget_s=1.0),
    # the default without tilted views (``--no-views``): the plain search in both orders only.
    # A "no" comes about 3 times sooner on 1 MP images, 1.5 to 2 times on 12-16 MP photos
    # (options.NO_VIEWS_SPEEDUP, measured in docs/design/SPEED.md), for batches over archives of mostly unrelated pairs, at the cost
    # of the tilted pairs only views solve (docs/results/NULLS.md, "Mode no-views";
    # docs/design/SPEED.md, 'The time of a "no"')
    "no-views": lambda: Config(views=ViewParams(enabled=False)),
    # the default with its answer allowed no further than an affine map, or than a homography
    # (``--model affine``, ``--model homography``: plan.CEILINGS), so that the null set can
    # be run with each (docs/results/NULLS.md, "Mode homography")
    "affine": lambda: Config(model="affine"),
    "homography": lambda: Config(model="homography"),
    # a homography searched for at every scale (the model check off), as the paper's method
    # fits the model asked for
    "homography-searched": lambda: Config(model="homography",
                                          model_check=ModelCheckParams(enabled=False)),
    # the default searching for a fundamental matrix (``--model fundamental``: 3-D scenes), so
    # that the null set can be run with it (docs/results/NULLS.md, "Mode fundamental")
    "fundamental": lambda: Config(model="fundamental"),
    # the default without the rotation-consistency filter: one group holding every candidate
    "default-no-rotation-check": lambda: Config(
        orientation=OrientationParams(tolerance_deg=180.0, max_peaks=1)),
}
