"""The plain search: the finer image itself probed at every scale against the coarser image.

The coarser image is described once per direction, on a thread while the finer image is
detected (:func:`probe_plain`); the probe scores each scale from its strongest points
(:func:`score_view`, paper 5) and keeps the promising ones for the full match.
"""

from __future__ import annotations

import math
from typing import Tuple

from ..stages.estimator import FitSpec
from ..stages.nodata import distance_inside
from ..stages.probe import probe_scores, select_scales
from ..stages.threads import thread_map
from ..stages.views import View, identity_view
from .detect import Reuse, describe_low, detect_view
from .full import Candidate
from .plan import Step
from .shared import LowFeatures, Probed, Search


def score_view(view: View, detected: Tuple, probing: bool, low: LowFeatures,
               search: Search) -> Probed:
    """Score each scale of a detected view from its strongest points (paper 5)."""
    config = search.config
    usable = [i for i, d in enumerate(detected) if d.probe is not None and len(d.probe)]
    if probing:
        # the probe's quick fit is a similarity whatever the model searched for: its ratio
        # and angle are what rank the scales
        quick = FitSpec("similarity", config.ransac, config.seed)
        scores = probe_scores([detected[i].probe for i in usable], low.described, config.probe,
                              matcher=config.matcher, orientation=search.mode.orientation,
                              fit=quick, scale_agreement=config.decision.scale_agreement)
        run = sorted(usable[j] for j in select_scales(scores, config.probe.keep,
                                                               config.probe.min_score))
        best = max(scores, default=0.0)
    else:
        run, best = usable, math.inf
    return Probed(view, detected, tuple(usable), tuple(run), best, probing)


def probe_plain(search: Search, step: Step) -> Candidate:
    """Detect and probe the finer image itself at every scale against the coarser image, which
    is described once per direction (``memo.coarser``), on a thread while the finer image is
    detected; the finer image probed is kept (``memo.plain``) for the views."""
    cfg, memo, direction = search.config, search.memo, step.direction
    lo_img, hi_img = search.work.coarser_finer(direction)
    lo_valid, hi_valid = search.work.valid(direction)
    view = identity_view(hi_img, hi_valid)

    def detect():  # the gradients measured with the contrast serve the image's s = 1 level
        reuse = Reuse(memo.coarser.get(direction.other), memo.measured(hi_img, cfg.harris))
        return detect_view(view, search, step.scales, search.meter.tick, reuse)

    if direction not in memo.coarser:  # described while the finer image is detected
        memo.coarser[direction], detected = thread_map(lambda job: job(), [
            lambda: describe_low(lo_img, search, *memo.measured(lo_img, cfg.harris_low),
                                 distance_inside(lo_valid)),
            detect])
    else:
        detected = detect()
    probed = score_view(view, *detected, memo.coarser[direction], search)
    memo.plain[direction] = probed
    return Candidate(probed, memo.coarser[direction], None, direction, tuple(sorted(step.scales)),
                     probed.score)
