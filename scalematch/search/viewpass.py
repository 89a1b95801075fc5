"""A pass of views: every view of both images described once, one pooled vote, the best pairs.

ASIFT's simulated tilts (Morel & Yu 2009) of both images are described once
(:mod:`scalematch.search.features`), one vote pools every view pair of every direction
searched (:func:`side_cells`, :mod:`scalematch.stages.vote`), and the view pairs of the
strongest cells beyond chance are made again at full resolution (:func:`view_pair`) and
matched in full (:func:`scalematch.search.full.match_chosen`).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Dict, List, Sequence, Tuple

import numpy as np

from ..result import Direction, StepRecord
from ..stages.matcher import match_descriptors
from ..stages.views import identity_view, tilt_view, view_scales
from ..stages.vote import Candidates as VoteCandidates
from ..stages.vote import Cells, Ranked, best_pairs, index_scale, scale_index
from ..stages.vote import log10_nfa as cells_nfa
from ..stages.vote import vote as vote_cells
from .detect import coarser_described, describe_coarser_view, detect_chosen, plain_probed, space_of
from .features import Describing, ImageViews, Roles, image_views
from .full import Candidate, match_chosen
from .plan import Attempt, Step, coarser_viewed, finer_sides
from .shared import Search


def run_views(search: Search, step: Step, searches: int) -> Tuple[List[Attempt], StepRecord]:
    """The step of views: every view of both images described once (:mod:`scalematch.search.features`),
    one pooled vote over every view pair of every direction searched
    (:mod:`scalematch.stages.vote`), and the ``step.full_searches`` view pairs whose best cell
    is strongest, beyond chance, matched in full and decided; (attempts, record).

    A direction's view pairs are its finer image's views against its coarser image itself
    (``finer``), and its finer image itself against its coarser image's views (``coarser``,
    ``ViewParams.coarser``); the images themselves were searched by the plain steps.
    """
    cfg, work = search.config, search.work
    directions = [d for d, _ in step.directions]
    scales = dict(step.directions)
    viewed = coarser_viewed(directions, finer_sides(work), cfg.views.coarser_directions) \
        if cfg.views.coarser else ()
    images = views_of_images(search, step, viewed)
    sides: List[Tuple[Direction, str]] = []
    cells: List[Cells] = []
    for d in directions:
        coarser, finer = d.coarser_finer(images[Direction.GIVEN], images[Direction.SWAPPED])
        sides.append((d, "finer"))
        cells.append(side_cells(finer, coarser, "finer", cfg.matcher, cfg.vote))
        if d in viewed:
            sides.append((d, "coarser"))
            cells.append(side_cells(finer, coarser, "coarser", cfg.matcher, cfg.vote))
    # every cell voted so far counts, the earlier passes' too
    search.memo.cells_tried += sum(c.tried for c in cells)
    nfa = [cells_nfa(c, search.memo.cells_tried) for c in cells]
    ranked = best_pairs(cells, nfa, step.full_searches, cfg.vote)
    pairs = sum(len(step.views) for _, side in sides)
    chosen = [view_pair(search, sides[r.side][0], images, r, scales[sides[r.side][0]])
              for r in ranked]
    attempts = match_chosen(search, step, chosen, searches + pairs)
    # the record names the first direction searched; its side, "both", says both were
    record = StepRecord(directions[0], step.view_pass, pairs, len(attempts),
                        max((r.votes for r in ranked), default=0),
                        any(a.matched for a in attempts), "both")
    return attempts, record


def views_of_images(search: Search, step: Step, viewed: Sequence[Direction]
                    ) -> Dict[Direction, ImageViews]:
    """Each image's views and tables, keyed by the direction in which it is the coarser one
    (``GIVEN``: the first image given, ``SWAPPED``: the second), as far as the step needs them:
    as the finer image of a direction searched, every level of its views; as the coarser image
    of a direction in ``viewed``, the first level of its views. The images themselves come
    from the plain steps' detection (:func:`plain_probed`, :func:`coarser_described`)."""
    cfg, work, memo = search.config, search.work, search.memo
    scales = dict(step.directions)
    out = {}
    for d in (Direction.GIVEN, Direction.SWAPPED):
        image = d.coarser_finer(work.low, work.high)[0]
        valid = d.coarser_finer(work.low_valid, work.high_valid)[0]
        finer_scales = scales.get(d.other, ())  # this image is the other direction's finer one
        plain = plain_probed(search, d.other, finer_scales) if finer_scales else None
        coarser = coarser_described(search, d) if d in scales else None
        how = Describing(search.mode.describe, cfg.harris, cfg.harris_low,
                         memo.contrast(image, cfg.harris), space_of(cfg), cfg.probe.points,
                         cfg.views.edge_margin_px, cfg.views.vote_every,
                         cfg.harris.min_level_side_px, cfg.views.finer_from_scale)
        roles = Roles(plain.view if plain is not None else identity_view(image, valid),
                      [x.probe for x in plain.detected if x.probe is not None]
                      if plain is not None else [],
                      coarser.described if coarser is not None else None, finer_scales,
                      d in viewed)
        out[d] = image_views(image, valid, roles, step.views, cfg.views, how, search.meter.tick)
    return out


def side_cells(finer: ImageViews, coarser: ImageViews, side: str, matcher, params) -> Cells:
    """The cells of one side of a direction's vote: the finer image's tilted views (all their
    levels probed) against the coarser image itself (``"finer"``), or the finer image itself
    (every scale probed) against each tilted view of the coarser image (``"coarser"``: the
    ratio test within each view, as a search of that view alone)."""
    f, c = finer.finer, coarser.coarser
    if side == "finer":
        f_rows, c_parts = f.rows(f.view > 0), [c.rows(c.view == 0)]
    else:
        f_rows = f.rows(f.view == 0)
        c_parts = [c.rows(c.view == v) for v in np.unique(c.view[c.view > 0])]
    found = []
    for part in c_parts:
        cand = match_descriptors(f_rows.desc, part.desc, matcher)
        if len(cand):
            i, j = cand.i, cand.j
            found.append(VoteCandidates(f_rows.view[i], part.view[j], f_rows.s[i] / part.s[j],
                                        f_rows.xy[i], part.xy[j], part.angle[j] - f_rows.angle[i],
                                        f_rows.point[i], part.point[j]))
    return vote_cells(VoteCandidates.joined(found), finer.sides, coarser.shapes, params)


def view_pair(search: Search, direction: Direction, images: Dict[Direction, ImageViews],
              ranked: Ranked, scales: Sequence[float]) -> Candidate:
    """A view pair the vote ranks among the best, made ready to be matched in full at full
    resolution (ASIFT's second resolution, Morel & Yu 2009, section 4): the finer view (made
    again at full resolution when the vote's was shrunk: ``ViewParams.max_short_side_px``) detected
    at the scales of its cells beyond chance and their neighbours (every point, the probe's
    described), the coarser view (made again the same way) described whole, or the coarser
    image itself."""
    cfg, memo, work = search.config, search.memo, search.work
    coarser_img, finer_img = direction.coarser_finer(images[Direction.GIVEN],
                                                     images[Direction.SWAPPED])
    lo_img, hi_img = work.coarser_finer(direction)
    lo_valid, hi_valid = work.valid(direction)
    voted_f = finer_img.views[ranked.finer_view]
    voted_c = coarser_img.views[ranked.coarser_view]
    full = replace(cfg.views, max_short_side_px=0.0)
    f_view = plain_probed(search, direction, scales).view if ranked.finer_view == 0 else \
        tilt_view(hi_img, voted_f.tilt, voted_f.longitude_deg, full, hi_valid)
    c_view = None if ranked.coarser_view == 0 else \
        tilt_view(lo_img, voted_c.tilt, voted_c.longitude_deg, full, lo_valid)
    own = view_scales(f_view, scales)
    # the vote's scales are between its views' pixels: in the full views' pixels, times theirs
    shift = voted_f.scale / voted_c.scale
    indices = scale_index(index_scale(np.array(ranked.scale_indices[:cfg.probe.keep])) * shift)
    wanted = sorted({k for si in indices for k in _near_scale(own, int(si)) if 0 <= k < len(own)})
    if f_view.is_identity:
        probed = replace(plain_probed(search, direction, scales), run=tuple(wanted),
                         score=float(ranked.votes))
    else:
        probed = detect_chosen(f_view, own, wanted, search, memo.contrast(hi_img, cfg.harris))
    low = coarser_described(search, direction) if c_view is None else describe_coarser_view(
        c_view, search, memo.contrast(lo_img, cfg.harris_low))
    return Candidate(probed, low, c_view, direction, tuple(own), float(ranked.votes))


def _near_scale(own: Sequence[float], index: int) -> List[int]:
    """The positions in ``own`` (a view's scales) of the scale of third-octave ``index`` and
    of its two neighbours."""
    at = int(np.argmin([abs(k - index) for k in scale_index(np.asarray(own))]))
    return [at - 1, at, at + 1]
