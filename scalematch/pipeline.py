"""The one-to-many matcher: every scale of the finer image against the coarser one (paper 4.2, 5).

``match(low, high, config)`` checks its inputs once, brings very large images to their working
size, builds one :class:`~scalematch.search.shared.Search` (the images, the configuration, the
mode's strategy from :mod:`scalematch.search.modes`, what the steps share, the progress meter)
and runs the search plan (:mod:`scalematch.search`) with it, a step at a time: each step detects
the views of the finer image at every scale (scale-adapted Harris), describes their strongest
points, scores the scales with the probe, and matches the promising ones in full against the
coarser image's points (found once, at s = 1): candidates, geometric constraints, robust
estimation. The scale with the most inliers wins (docs/ALGORITHM.md step 7) and
:mod:`scalematch.stages.decision` says whether the evidence is enough; :mod:`scalematch.answer`
makes the one :class:`MatchResult` of the attempts (the winner refit in the finer image's
pixels, its pixel tests, grown, pinned).
"""

from __future__ import annotations

import functools
import time
from dataclasses import replace
from typing import Callable, Optional, Tuple

import numpy as np

from .answer import (answered_by_a_matrix, build_result, plane_instead, plane_near_its_inliers,
                     without_parallax)
from .config import Config
from .greylevels import grey_levels
from .result import MatchResult, NoDataSeen
from .search.modes import mode_of
from .search.plan import finer_sides, search_plan
from .search.run import run_plan
from .search.shared import Memo, Meter, Search
from .stages.matcher import distinct_pairs
from .stages.nodata import NoData
from .working import WorkImages, at_working_size, in_original

__all__ = ["match", "distinct_pairs"]


def match(low: np.ndarray, high: np.ndarray, config: Config = Config(),
          progress: Optional[Callable[[int, int], None]] = None,
          decoded_factors: Tuple[float, float] = (1.0, 1.0)) -> MatchResult:
    """Match a low-resolution image against a high-resolution one of the same scene.

    ``low``, ``high``: (H, W) grey images (8-bit levels, 16-bit integers or floats in [0, 1];
    ``ValueError`` for what cannot match). ``config``: every parameter, recorded in the result.
    ``progress(done, total)`` follows the search plan. ``decoded_factors``: each image is its
    file's shrunk by this factor (a JPEG decoded reduced); the answer is in the files' pixels.

    Returns a :class:`MatchResult`: ``matched`` False with a ``reason`` when the evidence is too
    weak (a wrong transform reported as a match is the worst outcome); ``transform`` maps the
    finer image's pixels to the coarser one's, ``order`` says which image is the finer.
    """
    check_config(config)
    t0 = time.perf_counter()
    # 1. The images at their working size, checked at the door; their no-data found
    #    (working.py, stages/nodata.py)
    work = at_working_size(grey_levels(low, "low"), grey_levels(high, "high"), config,
                           decoded_factors)
    # 2-6. The search and its answer, in the images' own pixels
    result = searched_answer(work, config, progress, t0)
    # 7. A fundamental matrix whose inliers show no parallax does not fix its epipole, and
    #    none found says nothing of a flat scene: the plane map of the same images answers
    #    instead (answer.without_parallax, answer.plane_instead)
    if answered_by_a_matrix(config) and not (result.matched and result.evidence.parallax):
        plane = searched_answer(work, replace(config, model=config.decision.plane_model),
                                None, time.perf_counter())
        result = without_parallax(result, plane, config,
                                  plane_near_its_inliers(plane, work, config)) \
            if result.matched else plane_instead(result, plane)
    return result


def searched_answer(work: WorkImages, config: Config,
                    progress: Optional[Callable[[int, int], None]], t0: float) -> MatchResult:
    """The search of images at their working size ``work`` with ``config``, and its answer in
    the images' own pixels (``match``'s steps 2 to 6; ``t0``: when the search's time began,
    ``time.perf_counter``)."""
    # 2. The plan (search/plan.py, MODS): the given order, the other, then passes of tilted views
    plan = search_plan(config, work.scales, finer_sides(work))
    # 3. What every step shares: the mode's strategy (search/modes.py), the caches, the progress meter
    search = Search(work, config, mode_of(config), Memo(),
                    Meter(progress, sum(step.cost for step in plan)))
    # 4. Each step until one decides: the scale-space of the finer image and Harris points at
    #    every scale, descriptors, the probe, then matching, constraints and RANSAC at the
    #    scales it chose, and the decision (search/run.py, stages/decision.py)
    run = run_plan(search, plan, t0)
    # 5. The answer: the winner refit, judged by its pixels and grown; or a "no" and why
    #    (answer.py)
    result = build_result(search, run)
    # 6. In the images' own pixels, with what each showed of no-data
    return replace(in_original(result, work, config),
                   nodata=(nodata_seen(work.low_nodata), nodata_seen(work.high_nodata)))


def check_config(config: Config) -> None:
    """``TypeError`` unless ``config`` is a :class:`Config`; the process's BLAS warmed up."""
    if not isinstance(config, Config):
        raise TypeError(f"config must be a scalematch.Config, not {type(config).__name__}: "
                        f"Config(model=\"affine\") or Config.preset(\"no-views\"), say")
    warm_up_blas()


def nodata_seen(nodata: NoData) -> NoDataSeen:
    """The record of what an image showed of no-data (the JSON's ``low.nodata``)."""
    return NoDataSeen(nodata.value, nodata.share)


@functools.cache
def warm_up_blas() -> None:
    """Run one small matrix product, once per process.

    OpenBLAS allocates its work buffers at its first matrix product, and when that allocation
    fails (a process near its memory limit) it ends the process with exit code 1 from native
    code, which reads as "no reliable match". One small product before the images are worked on
    (at the start of ``match``, and when a batch worker starts) takes them while memory is
    there; later products reuse them.
    """
    np.ones((128, 128), np.float32) @ np.ones((128, 128), np.float32)
