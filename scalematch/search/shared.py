"""What the steps of one search compute once and share.

None of it changes an answer: a value found once is the value found again (the tests of
``tests/test_pipeline.py`` compare both ways). A change to a stage of the method (``stages/``)
does not need this module read:

* :class:`Memo`: each direction's coarser image described once, each direction's finer image
  detected once (the views' vote reads both), each image's contrast measured once;
* :class:`Measured`: an image's contrast and the gradients it was measured from;
* :class:`LowFeatures`, :class:`Detected`, :class:`Probed`: an image described once as the
  coarser one, and detected once at every scale as the finer one, as the memo keeps them;
* :class:`Meter`: the progress of the plan, counted across threads;
* :class:`Search`: what every step of one search shares, these among it.

The threads themselves are :mod:`scalematch.stages.threads`'.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Callable, Dict, NamedTuple, Optional, Tuple

import numpy as np

from ..config import Config
from .modes import Mode
from ..result import Direction
from ..stages.descriptors import Described
from ..stages.detector import Contrast, Gradients, Keypoints, gradients, image_contrast
from ..stages.scalespace import Level
from ..stages.views import View
from ..working import WorkImages

class Measured(NamedTuple):
    """What :meth:`Memo.measured` gives of an image: its contrast (None: the detector does not
    adapt to it) and the gradients it was measured from (None: taken already, or not kept)."""

    contrast: Optional[Contrast]
    gradients: Optional[Gradients] = None


@dataclass(frozen=True)
class LowFeatures:
    """The coarser image described once, at s = 1 (docs/ALGORITHM.md step 1: I' at s = 1)."""

    image: np.ndarray = field(repr=False)  #: (H, W) float32
    described: Described = field(repr=False)
    keypoints: Keypoints = field(repr=False)  #: strongest first (``harris_low``)

    def strongest(self, n_points: int, n_described: int) -> Tuple[Keypoints, Described, Described]:
        """(keypoints, descriptors of the ``n_described`` strongest, of all) of the ``n_points``
        strongest points: what detecting and describing the same image at s = 1 with a cap of
        ``n_points`` gives (detection sorts strongest first and caps last; a point's
        descriptors depend on that point alone)."""
        kp = self.keypoints.part(slice(n_points))
        d = self.described
        return kp, d.of_strongest(min(n_described, len(kp))), d.of_strongest(len(kp))


class Detected(NamedTuple):
    """One scale of a view, detected and (its probe's points) described."""

    keypoints: Keypoints
    #: descriptors of the probe's points (of every point without the probe); None: too small
    probe: Optional[Described]
    level: Optional[Level]  #: the level, when kept for the full pass
    #: every point described already (s = 1, shared with the other direction), or None
    full: Optional[Described] = None


@dataclass(frozen=True)
class Probed:
    """A view of the finer image detected at every scale and scored by the probe."""

    view: View = field(repr=False)
    detected: Tuple[Detected, ...] = field(repr=False)  #: per scale
    usable: Tuple[int, ...]  #: scales with described points
    run: Tuple[int, ...]  #: scales to match in full
    score: float  #: the best probe score over the scales (inf when the probe is off)
    probing: bool


@dataclass
class Memo:
    """What the steps of one search compute once and share: each direction's coarser image
    described and finer image detected, and each image's contrast (a "no" runs the plain
    search in both orders and then the views over the same two images; the contrast alone is a
    full-image percentile)."""

    coarser: Dict[Direction, LowFeatures] = field(default_factory=dict)
    #: each direction's finer image detected at every scale by its plain step (``Probed``),
    #: which the views' vote reads
    plain: Dict[Direction, Probed] = field(default_factory=dict)
    #: cells of the views' votes so far: the a-contrario count of a pass counts the earlier's
    cells_tried: int = 0
    _contrasts: Dict[tuple, Contrast] = field(default_factory=dict, repr=False)
    #: the gradients each contrast was measured from, until the image's s = 1 detection
    _gradients: Dict[tuple, Gradients] = field(default_factory=dict, repr=False)
    _locks: Dict[tuple, threading.Lock] = field(default_factory=dict, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def contrast(self, image: np.ndarray, params) -> Optional[Contrast]:
        """``image_contrast(image, params)`` once per image (None: not adaptive). Threads
        asking for the same image wait for the one measuring it; two images are measured side
        by side (the coarser image is described on a thread while the finer one is detected)."""
        return self.measured(image, params, take=False)[0]

    def measured(self, image: np.ndarray, params, take: bool = True) -> "Measured":
        """(contrast, gradients): the image's contrast (:meth:`contrast`) and, the first time
        they are taken (``take``), the gradients it was measured from, which the image's s = 1
        Harris response shares (None after that, or when not adaptive)."""
        if not params.adaptive:
            return Measured(None, None)
        # the same measure for every detector of the same sigma and contrast parameters
        key = (id(image), float(params.sigma), params.contrast_percentile,
               params.contrast_sample_step)
        with self._lock:
            lock = self._locks.setdefault(key, threading.Lock())
        with lock:
            if key not in self._contrasts:
                grads = gradients(image, params.sigma)
                self._contrasts[key] = image_contrast(image, params, grads)
                self._gradients[key] = grads
            return Measured(self._contrasts[key],
                            self._gradients.pop(key, None) if take else None)


class Meter:
    """``progress(done, total)`` over the plan: one unit per scale detected or matched."""

    def __init__(self, progress: Optional[Callable[[int, int], None]], total: int) -> None:
        self.progress, self.total, self.done = progress, total, 0
        self._lock = threading.Lock()  # views are detected on threads

    def tick(self, units: int = 1) -> None:
        with self._lock:
            self.done = done = min(self.done + units, self.total)
            if self.progress is not None:
                self.progress(done, self.total)

    def finish(self) -> None:
        if self.done < self.total:
            self.tick(self.total - self.done)


@dataclass(frozen=True)
class Search:
    """What every step of one search shares, built once by :func:`scalematch.pipeline.match`: the images at
    their working size, the configuration, the mode's strategy (:func:`scalematch.search.modes.mode_of`),
    what the steps compute once (``memo``) and the progress meter.

    The scales a step searches are its own (``Step.scales``: its direction's, within reach);
    the functions that detect or match take them as ``scales``, never from ``config``.
    """

    work: WorkImages = field(repr=False)
    config: Config
    mode: Mode
    memo: Memo = field(repr=False)
    meter: Meter = field(repr=False)
