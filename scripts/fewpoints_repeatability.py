"""Repeatability study with the adaptive options off / on (docs/FEWPOINTS.md). Run: .venv/bin/python scripts/fewpoints_repeatability.py"""
import time, glob
from scalematch.lab.repeatability import run_study, StudyParams, format_table
from scalematch.stages.detector import HarrisParams
paths = sorted(glob.glob('/work/shared/data/photos/*.[jJ][pP]*'))[::5][:6]
for name, hp in (("off", HarrisParams()), ("relative", HarrisParams(contrast_relative=True)), ("relative+budget100", HarrisParams(contrast_relative=True, min_points=100))):
    t0 = time.perf_counter()
    tab = run_study(paths, factors=(1.0, 2.0, 4.0, 6.0), seed=0, params=StudyParams(harris=hp))
    print('##', name, f'{time.perf_counter()-t0:.0f} s, photos', len(tab.photos))
    print(format_table(tab))
    import numpy as np
    for r in (1.0, 2.0, 4.0, 6.0):
        at = [p for p in tab.pairs if p.factor == r]
        print(f"  r={r:g}: mean n_high_adapted {np.mean([p.n_high_adapted for p in at]):.0f}, n_low {np.mean([p.n_low for p in at]):.0f}")
