"""What the steps of one search compute once and share, and the bounds on what they keep.

None of it changes an answer: a value found once is the value found again, and what is not kept
is made again, the same (the tests of ``tests/test_pipeline.py`` compare both ways). A change to
a stage of the method (``stages/``) does not need this module read:

* :class:`Memo`: each direction's coarser image described once, each image's contrast measured
  once, the views of a pass made once within ``VIEW_CACHE_MAX_BYTES``, and the s = 1 points a
  view's finer side found for its coarser side;
* :class:`Measured`: an image's contrast and the gradients it was measured from;
* :class:`Leaders`: of the views of a step, only the best few keep their scale-space levels;
* :class:`Meter`: the progress of the plan, counted across threads.

The threads themselves are :mod:`scalematch.stages.threads`'.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Dict, List, NamedTuple, Optional, Tuple

import numpy as np

from .result import Direction
from .stages.detector import Contrast, Gradients, gradients, image_contrast
from .stages.views import View

if TYPE_CHECKING:  # the pipeline's own records, named in annotations only
    from .pipeline import FirstLevel, LowFeatures, Probed

#: Bytes of tilted views a search keeps while it searches one pass of views (:meth:`Memo.view`).
#: A pass views each image twice, as the finer image of one direction and as the coarser image
#: of the other, with the same views: a view kept is made once. A view past the budget is made
#: again, the same view; the budget bounds what a pair of camera-size images adds to the peak.
VIEW_CACHE_MAX_BYTES = 100_000_000


class Measured(NamedTuple):
    """What :meth:`Memo.measured` gives of an image: its contrast (None: the detector does not
    adapt to it) and the gradients it was measured from (None: taken already, or not kept)."""

    contrast: Optional[Contrast]
    gradients: Optional[Gradients] = None


@dataclass
class Memo:
    """What the steps of one search compute once and share: each direction's coarser image
    described, and each image's contrast (a "no" runs up to six steps over the same two
    images; the contrast alone is a full-image percentile)."""

    coarser: Dict[Direction, LowFeatures] = field(default_factory=dict)
    #: each direction's finer image detected at every scale by its pass 0 (``Probed``), which
    #: the views of the coarser image are probed and matched against
    plain: Dict[Direction, "Probed"] = field(default_factory=dict)
    _contrasts: Dict[tuple, Contrast] = field(default_factory=dict, repr=False)
    #: the gradients each contrast was measured from, until the image's s = 1 detection
    _gradients: Dict[tuple, Gradients] = field(default_factory=dict, repr=False)
    _locks: Dict[tuple, threading.Lock] = field(default_factory=dict, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    #: the views of one pass (``_view_pass``) by (image, view key), and their bytes
    _views: Dict[tuple, View] = field(default_factory=dict, repr=False)
    _view_bytes: int = 0
    _view_pass: int = -1
    #: the s = 1 points of those views as the finer side found them (:class:`FirstLevel`)
    _firsts: Dict[tuple, "FirstLevel"] = field(default_factory=dict, repr=False)
    #: the first look's searches of the shrunk images, by factor (:meth:`small`)
    _small: Dict[tuple, Any] = field(default_factory=dict, repr=False)
    _small_locks: Dict[tuple, threading.Lock] = field(default_factory=dict, repr=False)

    def _enter(self, view_pass: int) -> None:
        """Forget the views of another pass (called with ``_lock`` held)."""
        if view_pass != self._view_pass:
            self._views.clear()
            self._firsts.clear()
            self._view_bytes, self._view_pass = 0, view_pass

    def view(self, image: np.ndarray, key: Tuple[float, float], view_pass: int,
             make: Callable[[], View]) -> View:
        """The view ``key`` (tilt, longitude) of ``image`` in pass ``view_pass``: ``make()``
        the first time, kept within ``VIEW_CACHE_MAX_BYTES`` for the rest of the pass."""
        if key[0] <= 1.0:  # the image itself: nothing to make
            return make()
        k = (id(image), *key)
        with self._lock:
            self._enter(view_pass)
            kept = self._views.get(k)
        if kept is not None:
            return kept
        view = make()
        size = view.image.nbytes + getattr(view.inside_distance, "nbytes", 0)
        with self._lock:
            if view_pass == self._view_pass and self._view_bytes + size <= VIEW_CACHE_MAX_BYTES:
                self._views[k] = view
                self._view_bytes += size
        return view

    def small(self, k: float, make: Callable[[], Any]) -> Any:
        """The first look's search of the images shrunk by ``k``: ``make()`` the first time,
        kept for the rest of the search (its memo keeps the shrunk images' own work: each
        direction's coarser image described, the contrasts, the finer image's plain scales)."""
        key = k
        with self._lock:
            lock = self._small_locks.setdefault(key, threading.Lock())
        with lock:
            if key not in self._small:
                self._small[key] = make()
            return self._small[key]

    def forget_views(self) -> None:
        """Drop the views kept for the last pass (the search is over)."""
        with self._lock:
            self._enter(-1)

    def keep_first(self, image: np.ndarray, key: Tuple[float, float], view_pass: int,
                   first: "FirstLevel") -> None:
        """Keep the s = 1 points the finer side found on a view (for :meth:`first_level`)."""
        with self._lock:
            self._enter(view_pass)
            self._firsts[(id(image), *key)] = first

    def first_level(self, image: np.ndarray, key: Tuple[float, float],
                    view_pass: int) -> Optional["FirstLevel"]:
        """The s = 1 points of view ``key`` of ``image`` kept by :meth:`keep_first` in this
        pass (None: not found by the finer side)."""
        with self._lock:
            self._enter(view_pass)
            return self._firsts.get((id(image), *key))

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


class Leaders:
    """The views of a step as they are probed (``probed``, in the step's order), where only
    the ``keep`` best so far keep their scale-space levels: the views matched in full are
    among the best ``full_searches`` (:func:`match_chosen`), and the levels of every view of a
    pass were most of a search's peak memory. Best: highest score, the earlier view on a tie
    (the order of ``sorted(..., key=-score)``). A view that leaves the best never returns (the
    bar only rises); were it chosen after all, its levels would be made again, the same."""

    def __init__(self, keep: int, drop: Callable[[Any], Any]) -> None:
        self.keep, self.drop = keep, drop
        self.probed: List[Any] = []
        self._best: List[int] = []
        self._lock = threading.Lock()

    def add(self, k: int, probed: Any) -> None:
        """Record view ``k``'s probe; the levels of the view that leaves the best are dropped."""
        with self._lock:
            self.probed.extend([None] * (k + 1 - len(self.probed)))
            self.probed[k] = probed
            self._best.append(k)
            if len(self._best) > self.keep:
                worst = max(self._best, key=lambda j: (-self.probed[j].score, j))
                self._best.remove(worst)
                self.probed[worst] = self.drop(self.probed[worst])


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
