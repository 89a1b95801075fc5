"""The regression gate (``lab.regress``): the sample, the judge, the comparison with the
baseline and the command's exits, on known answers."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from scalematch.geometry import invert
from scalematch.lab import regress
from scalematch.lab.regress import Case, compare, failures, judge, spread, table

ROOT = Path(__file__).resolve().parents[2]


def test_spread_takes_distinct_indices_evenly():
    for n, count, offset in ((38, 3, 5), (38, 5, 37), (5, 2, 4)):
        idx = spread(n, count, offset)
        assert len(set(idx)) == count and all(0 <= i < n for i in idx)
    assert spread(38, 2, 0) == [0, 19]


def _case(order: str = "given", truth=None, kind: str = "zoom") -> Case:
    img = np.zeros((40, 60), np.float32)
    t = np.array([[0.25, 0, 10.0], [0, 0.25, 5.0], [0, 0, 1.0]]) if truth is None else truth
    return Case(kind, "a x4", order, img, img, None if kind.startswith("null") else t)


def _answer(transform, order="given", matched=True):
    return {"matched": matched, "seconds": 0.5, "order": order, "model": "similarity",
            "inliers": 20, "reason": "", "transform": None if transform is None
            else np.asarray(transform).tolist()}


def test_the_judge_solves_the_truth_either_way_round_and_counts_a_miss_as_wrong():
    c = _case()
    right = judge(c, _answer(c.truth[:2]))
    assert right["solved"] and not right["wrong"] and right["error_px"] == 0.0
    # the swapped run: the answer still maps the finer image (given second... here first)
    swapped = _case("swapped")
    assert judge(swapped, _answer(swapped.truth[:2], order="swapped"))["solved"]
    # an answer that took the other image as the finer one, inverted, is the same map
    assert judge(c, _answer(invert(c.truth)[:2], order="swapped"))["solved"]
    off = c.truth.copy()
    off[0, 2] += 5.0  # 5 coarser px off
    wrong = judge(c, _answer(off[:2]))
    assert wrong["wrong"] and not wrong["solved"] and wrong["error_px"] == pytest.approx(5.0)
    no = judge(c, _answer(None, matched=False))
    assert not no["solved"] and not no["wrong"] and no["error_px"] is None


def test_any_claim_on_a_null_pair_is_wrong():
    null = _case(kind="null-unrelated")
    assert judge(null, _answer(np.eye(3)[:2]))["wrong"]
    assert not judge(null, _answer(None, matched=False))["wrong"]


def _row(i: str, solved: bool, wrong: bool = False, kind: str = "zoom", s: float = 1.0):
    return {"id": f"{kind}|{i}|given", "kind": kind, "solved": solved, "wrong": wrong,
            "claimed": solved or wrong, "error_px": 0.1 if solved else None, "seconds": s}


def test_compare_finds_lost_gained_and_new_wrong_claims():
    base = {r["id"]: r for r in [_row("a", True), _row("b", False), _row("c", True, s=2.0),
                                 _row("n", False, kind="null-unrelated")]}
    now = [_row("a", False), _row("b", True), _row("c", True, s=1.0),
           _row("n", False, True, kind="null-unrelated"), _row("new", True)]
    reports = {k.kind: k for k in compare(now, base)}
    zoom = reports["zoom"]
    assert zoom.lost == ("zoom|a|given",) and zoom.gained == ("zoom|b|given",)
    assert zoom.solved == 3 and zoom.base_solved == 2 and zoom.unmatched == 1
    assert zoom.median_s == 1.0 and zoom.base_median_s == 1.0
    assert reports["null-unrelated"].new_wrong == ("null-unrelated|n|given",)
    bad = failures(list(reports.values()))
    assert bad == ["lost: zoom|a|given", "new wrong claim: null-unrelated|n|given"]
    text = table(list(reports.values()))
    assert "| zoom | 4 | 3 | 2 | 1 | 1 | 0 | 0 | 2 |" in text  # a and b moved, c did not


def test_a_wrong_claim_the_baseline_made_too_is_not_new():
    base = {r["id"]: r for r in [_row("w", False, True)]}
    assert not compare([_row("w", False, True)], base)[0].new_wrong


def test_the_baseline_file_round_trips_one_row_per_line(tmp_path):
    path = tmp_path / "b.json"
    rows = [_row("b", True), _row("a", False, kind="ef")]
    regress.write_baseline(path, {"commit": "abc"}, rows)
    meta, back = regress.read_baseline(path)
    assert meta == {"commit": "abc"} and set(back) == {r["id"] for r in rows}
    lines = path.read_text().splitlines()
    assert len(lines) == 2 + len(rows) + 1  # meta, "rows": [, a line each, ]}
    assert json.loads(path.read_text())["rows"][0]["kind"] == "zoom"  # in the table's order


def test_run_cases_matches_in_workers_from_a_source_tree():
    """Two cases of the demo pair (both orders) through worker processes importing
    scalematch from this repository: solved, the rows in the cases' order."""
    from scalematch.imageio import read_grey

    low = read_grey(ROOT / "data" / "demo_low.png")
    high = read_grey(ROOT / "data" / "demo_high.png")
    # the demo's truth is not stored: take it from one match, then check the other order
    from scalematch import match

    t = np.vstack([match(low, high).transform, [0, 0, 1]])
    cases = [Case("zoom", "demo", "given", low, high, t),
             Case("zoom", "demo", "swapped", high, low, t)]
    rows, source = regress.run_cases(cases, jobs=1, tree=str(ROOT))
    assert Path(source) == ROOT
    assert [r["id"] for r in rows] == ["zoom|demo|given", "zoom|demo|swapped"]
    assert all(r["solved"] for r in rows), rows


def test_the_command_needs_the_shared_folder_unless_told_to_skip(tmp_path):
    runner = CliRunner()
    out = runner.invoke(regress.regress_command, ["--shared", str(tmp_path)])
    assert out.exit_code == 2 and "shared folder" in out.output
    out = runner.invoke(regress.regress_command, ["--shared", str(tmp_path), "--if-shared"])
    assert out.exit_code == 0 and "skipped" in out.output
    out = runner.invoke(regress.regress_command, ["--kinds", "zoom,nope"])
    assert out.exit_code == 2 and "unknown kind 'nope'" in out.output


def test_every_kind_is_made_in_both_orders_with_unique_ids(shared_dir):
    """The first cases of each kind (the generators are lazy): both orders, the truth where
    there is one, the 3-D pairs with their points, the nulls with none."""
    for kind in regress.KINDS:
        first = []
        for case in regress.cases(shared_dir, [kind]):
            first.append(case)
            if len(first) == 2:
                break
        assert [c.order for c in first] == ["given", "swapped"], kind
        assert first[0].kind == kind and len({c.id for c in first}) == 2
        if kind in regress.NULL_KINDS:
            assert first[0].truth is None and first[0].points is None
        elif kind in ("ef", "3d-pairs"):
            assert first[0].points.shape[1] == 4 and first[0].model == "fundamental"
        else:
            assert first[0].truth.shape == (3, 3)
        assert first[0].low.dtype == np.float32 and first[0].low.max() <= 255


def test_a_preset_with_settings_is_the_configuration_of_every_run():
    """``--preset tilt-4+views.max_short_side_px=500`` runs the tilt-4 preset with that value; an unknown
    preset or parameter is refused before the run (exit 2)."""
    from scalematch.config import Config
    from scalematch.options import set_path

    config = regress.configured("tilt-4+views.max_short_side_px=500", Config, set_path)
    base = Config.preset("tilt-4")
    assert config == replace(base, views=replace(base.views, max_short_side_px=500.0))
    runner = CliRunner()
    for bad in ("nope", "tilt-4+views.bogus=1"):
        out = runner.invoke(regress.regress_command, ["--preset", bad, "--kinds", "zoom"])
        assert out.exit_code == 2 and "--preset" in out.output, out.output
