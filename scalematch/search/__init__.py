"""The search: which finer image, at which scales and through which views, is matched in full.

In the order a match runs it (:func:`scalematch.search.run.run_plan`):

1. :mod:`.plan`: the plan of steps (the given order, the other, then passes of tilted views),
   the records of what each step found (``Attempt``, ``SearchRun``) and when the search stops;
2. :mod:`.shared`: what the steps share (``Search``: the images, the configuration, the mode,
   the caches of ``Memo``, the progress ``Meter``), with :mod:`.modes`, the two modes'
   strategies (how points are described and which candidates reach the estimator);
3. :mod:`.detect`: every view and level detected and described, the coarser image once;
4. :mod:`.plain`: the plain steps, the finer image itself probed at every scale;
5. :mod:`.viewpass`: a pass of views, both images' views described once (:mod:`.features`)
   and one pooled vote over every view pair, its best pairs made again at full resolution;
6. :mod:`.full`: the chosen scales of a view pair matched in full and decided;
7. :mod:`.run`: the plan run a step at a time.

Its attempts go to :mod:`scalematch.answer`, which makes the one answer of them.
"""
