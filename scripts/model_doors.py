"""The doors of ``--model``: the gate's pairs run under each model, and what each solves that
another does not.

Usage: python scripts/model_doors.py [--kinds zoom,flat,oxford,oxford-zoom,perspective]
       [--models similarity,affine,homography] [--jobs 2] [--out FILE.jsonl]

The "one decision" issue asks that every pair the default solves be solved under every
``--model`` that can express its map (a similarity is an affine map and a homography), and that
the model answered be chosen by the evidence. This measures where that fails today: each pair
of the regression gate's ``--kinds`` (``scalematch.lab.regress.cases``, both orders, judged as
the gate judges them) is matched with the default configuration under each of ``--models``
(the 3-D pairs keep the fundamental matrix), one worker process per job. Prints, per kind and
model, the runs solved and the wrong claims, then every run whose outcome differs between two
models with each one's answer or reason. Rows are appended to ``--out`` (bench-out/ is not
committed). Needs ../shared.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scalematch.lab import regress  # noqa: E402


def rows_by_model(kinds, models, jobs, shared):
    """{model: [the gate's row of each run]} with every case's model set to ``model``."""
    cases = list(regress.cases(shared, kinds))
    got = {}
    for model in models:
        asked = [c if c.model == "fundamental" else dataclasses.replace(c, model=model)
                 for c in cases]
        got[model], _ = regress.run_cases(asked, jobs=jobs)
    return got


def summary(got) -> str:
    """A Markdown table: runs, solved and wrong per kind, one column pair per model."""
    models = list(got)
    kinds = list(dict.fromkeys(r["kind"] for r in next(iter(got.values()))))
    head = "| kind | runs | " + " | ".join(f"{m} solved | {m} wrong" for m in models) + " |"
    lines = [head, "|---|---:|" + "---:|---:|" * len(models)]
    for kind in kinds:
        cells = []
        for m in models:
            rows = [r for r in got[m] if r["kind"] == kind]
            cells += [str(sum(r["solved"] for r in rows)), str(sum(r["wrong"] for r in rows))]
        n = sum(r["kind"] == kind for r in got[models[0]])
        lines.append(f"| {kind} | {n} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def differences(got) -> str:
    """Every run whose outcome (solved, wrong, refused) differs between two models."""
    by_id = collections.defaultdict(dict)
    for model, rows in got.items():
        for r in rows:
            by_id[r["id"]][model] = r
    out = []
    for run, answers in by_id.items():
        outcomes = {("solved" if r["solved"] else "wrong" if r["wrong"] else "no")
                    for r in answers.values()}
        if len(outcomes) > 1:
            said = "; ".join(
                f"{m}: " + (f"{r['model']}, {r['inliers']} inliers, {r['error_px']} px"
                            if r["claimed"] else r["reason"][:80])
                for m, r in answers.items())
            out.append(f"- {run}: {said}")
    return "\n".join(out) or "(none)"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kinds", default="zoom,flat,oxford,oxford-zoom,perspective")
    ap.add_argument("--models", default="similarity,affine,homography")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared")
    ap.add_argument("--out", type=Path, default=ROOT / "bench-out" / "model-doors.jsonl")
    a = ap.parse_args()
    got = rows_by_model(a.kinds.split(","), a.models.split(","), a.jobs, a.shared)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    with a.out.open("a") as f:
        for model, rows in got.items():
            for r in rows:
                f.write(json.dumps(dict(r, asked=model)) + "\n")
    print(f"`python scripts/model_doors.py --kinds {a.kinds} --models {a.models}`\n")
    print(summary(got))
    print("\nRuns whose outcome differs between models:\n")
    print(differences(got))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
