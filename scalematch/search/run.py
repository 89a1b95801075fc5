"""The plan run a step at a time (:func:`run_plan`, :func:`run_step`): the plain steps
(:mod:`scalematch.search.plain`) and the passes of views (:mod:`scalematch.search.viewpass`),
each decided, until one stops the search (:func:`scalematch.search.plan.stop_reason`) or the
time budget is spent.
"""

from __future__ import annotations

import time
from typing import Dict, List, Sequence, Tuple

from ..result import StepRecord
from .full import match_chosen
from .plain import probe_plain
from .plan import Attempt, SearchRun, Step, out_of_time, skips, stop_reason
from .shared import Search
from .viewpass import run_views


def run_plan(search: Search, plan: Sequence[Step], t0: float) -> SearchRun:
    """Run the steps of ``plan`` in order, each unless an earlier attempt makes it needless
    (:func:`scalematch.search.plan.skips`), until one stops the search or the time budget (counted
    from ``t0``, ``time.perf_counter``) is spent."""
    config = search.config
    attempts: List[Attempt] = []
    records: List[StepRecord] = []
    timings: Dict[str, float] = {}
    stopped = "plan done"
    for step in plan:
        if skips(step, attempts, config):
            search.meter.tick(step.cost)
            continue
        if out_of_time(time.perf_counter() - t0, len(records), config):
            stopped = "time budget"
            break
        found, record, seconds = run_step(search, step, searches=sum(r.views for r in records))
        attempts += found
        records.append(record)
        timings[record.name] = seconds
        stopped = stop_reason(step, attempts, plan, config)
        if stopped:
            break
    search.meter.finish()
    timings["total"] = time.perf_counter() - t0
    return SearchRun(tuple(attempts), tuple(records), tuple(plan), stopped, timings)


def run_step(search: Search, step: Step,
             searches: int) -> Tuple[List[Attempt], StepRecord, float]:
    """Run one step of the plan: the finer image itself (probe its scales, match the promising
    ones in full, decide), or the pooled views (:func:`run_views`); (attempts, record,
    seconds).

    ``search.memo`` holds what earlier steps computed on the same images; ``searches`` counts
    the view pairs searched by earlier steps (the a-contrario test counts them all).
    """
    t0 = time.perf_counter()
    meter = search.meter
    start = meter.done
    if step.view_pass > 0:
        attempts, record = run_views(search, step, searches)
    else:
        candidate = probe_plain(search, step)
        attempts = match_chosen(search, step, [candidate], searches + 1)
        record = StepRecord(step.direction, 0, 1, len(attempts), candidate.chosen_by,
                            any(a.matched for a in attempts), step.side)
    meter.tick(start + step.cost - meter.done)  # what the step left out
    return attempts, record, time.perf_counter() - t0
