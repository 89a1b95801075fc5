"""What the steps of one search compute once and share.

None of it changes an answer: a value found once is the value found again (the tests of
``tests/test_pipeline.py`` compare both ways). A change to a stage of the method (``stages/``)
does not need this module read:

* :class:`Memo`: each direction's coarser image described once, each direction's finer image
  detected once (the views' vote reads both), each image's contrast measured once;
* :class:`Measured`: an image's contrast and the gradients it was measured from;
* :class:`Meter`: the progress of the plan, counted across threads;
* :class:`Search`: what every step of one search shares, these among it.

The threads themselves are :mod:`scalematch.stages.threads`'.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Dict, NamedTuple, Optional

import numpy as np

from .config import Config
from .modes import Mode
from .result import Direction
from .stages.detector import Contrast, Gradients, gradients, image_contrast
from .working import WorkImages

if TYPE_CHECKING:  # the pipeline's own records, named in annotations only
    from .pipeline import LowFeatures, Probed


class Measured(NamedTuple):
    """What :meth:`Memo.measured` gives of an image: its contrast (None: the detector does not
    adapt to it) and the gradients it was measured from (None: taken already, or not kept)."""

    contrast: Optional[Contrast]
    gradients: Optional[Gradients] = None


@dataclass
class Memo:
    """What the steps of one search compute once and share: each direction's coarser image
    described and finer image detected, and each image's contrast (a "no" runs the plain
    search in both orders and then the views over the same two images; the contrast alone is a
    full-image percentile)."""

    coarser: Dict[Direction, LowFeatures] = field(default_factory=dict)
    #: each direction's finer image detected at every scale by its plain step (``Probed``),
    #: which the views' vote reads
    plain: Dict[Direction, "Probed"] = field(default_factory=dict)
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
    their working size, the configuration, the mode's strategy (:func:`scalematch.modes.mode_of`),
    what the steps compute once (``memo``) and the progress meter.

    The scales a step searches are its own (``Step.scales``: its direction's, within reach);
    the functions that detect or match take them as ``scales``, never from ``config``.
    """

    work: WorkImages = field(repr=False)
    config: Config
    mode: Mode
    memo: Memo = field(repr=False)
    meter: Meter = field(repr=False)
