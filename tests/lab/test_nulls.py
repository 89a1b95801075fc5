"""The null set (``scalematch.lab.nulls``): pairs with no answer, the runner, its summary.

Pair construction on small synthetic photos (no ../shared needed); one end-to-end run on a
fixed sample of the shared photos, which must give no false claim.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from scalematch.lab.nulls import (KINDS, ORDERS, NullSpec, chart_keys, ensure_pairs, execute,
                                  false_claims, load_rows, make_pair, make_same_photo_null,
                                  make_tasks, make_unrelated_null, null_specs, percentiles,
                                  plot_distributions, rects_overlap, run_nulls, split_rects,
                                  summarise, write_nulls_doc)


def _photo(w: int, h: int, seed: int) -> np.ndarray:
    """A textured grey photo (H, W) float32: blurred noise stretched to 0..255."""
    noise = np.random.default_rng(seed).uniform(0, 255, (h, w)).astype(np.float32)
    return cv2.normalize(cv2.GaussianBlur(noise, (0, 0), 2.0), None, 0, 255, cv2.NORM_MINMAX)


@pytest.mark.parametrize("shape", [(600, 900), (900, 600)])  # landscape, portrait
@pytest.mark.parametrize("low_first", [True, False])
def test_split_rects_are_disjoint_halves_with_a_gap(shape, low_first):
    a, b, name = split_rects(shape, low_first)
    assert not rects_overlap(a, b)
    h, w = shape
    for x, y, rw, rh in (a, b):
        assert 0 <= x and 0 <= y and x + rw <= w and y + rh <= h
    along = 0 if w >= h else 1  # the cut runs across the longer side
    gap = abs(a[along] - b[along]) - a[along + 2]
    assert gap >= 32 and a[2:] == b[2:]
    assert name in ("left|right", "right|left", "top|bottom", "bottom|top")


@pytest.mark.parametrize("ratio", [2.0, 4.0, 16.0])
@pytest.mark.parametrize("photo_name", ["wide_a.png", "tall_b.png"])
def test_same_photo_null_regions_do_not_overlap(ratio, photo_name):
    photo = _photo(1400, 900, 1) if photo_name.startswith("wide") else _photo(900, 1400, 2)
    spec = NullSpec("same-photo", photo_name, photo_name, ratio, seed=3)
    pair = make_same_photo_null(photo, spec)
    # the high crop and the part of the photo the low image shows share no pixel
    assert not rects_overlap(pair.low_region, pair.high_rect), (pair.low_region, pair.high_rect)
    low_half, high_half, _ = split_rects(photo.shape, pair.split.split("|")[0] in ("left", "top"))
    assert not rects_overlap(pair.low_region, high_half)
    hx, hy, hw, hh = pair.high_rect
    assert (hx >= high_half[0] and hy >= high_half[1] and hx + hw <= high_half[0] + high_half[2]
            and hy + hh <= high_half[1] + high_half[3])
    assert pair.high.shape == (hh, hw) and pair.high.dtype == np.uint8
    assert pair.low.dtype == np.uint8 and pair.low.shape[0] <= 768 and pair.low.shape[1] <= 1024
    # the high image is exactly that crop of the photo (rounded to 8 bits)
    assert np.array_equal(pair.high, np.clip(np.rint(photo[hy:hy + hh, hx:hx + hw]), 0, 255))


def test_pairs_are_deterministic_from_the_seed():
    photos = {"a_1.png": _photo(1000, 800, 1), "b_1.png": _photo(1000, 800, 2)}
    for kind, high in (("same-photo", "a_1.png"), ("unrelated", "b_1.png")):
        spec = NullSpec(kind, "a_1.png", high, 4.0, seed=0)
        p1, p2 = make_pair(spec, photos.__getitem__), make_pair(spec, photos.__getitem__)
        assert np.array_equal(p1.low, p2.low) and np.array_equal(p1.high, p2.high)
        assert p1.low_region == p2.low_region and p1.high_rect == p2.high_rect
        other = make_pair(NullSpec(kind, "a_1.png", high, 4.0, seed=1), photos.__getitem__)
        assert not (np.array_equal(other.low.shape, p1.low.shape)
                    and np.array_equal(other.low, p1.low))


def test_unrelated_null_takes_the_high_crop_from_the_other_photo():
    a, b = _photo(1000, 800, 1), _photo(1000, 800, 2)
    pair = make_unrelated_null(a, b, NullSpec("unrelated", "a_1.png", "b_1.png", 3.0, seed=0))
    x, y, w, h = pair.high_rect
    assert np.array_equal(pair.high, np.clip(np.rint(b[y:y + h, x:x + w]), 0, 255))


def test_specs_pair_other_scenes_only_and_interleave_the_kinds():
    names = ["a_1.jpg", "a_2.jpg", "b_1.jpg", "c_1.jpg"]
    specs = null_specs(names, ratios=(2, 8), seed=0)
    assert len(specs) == 2 * len(names) * 2  # every photo, ratio and kind
    for s in specs:
        if s.kind == "unrelated":
            assert s.high_photo.split("_")[0] != s.photo.split("_")[0]
        else:
            assert s.high_photo == s.photo
    assert [s.kind for s in specs[:4]] == list(KINDS) * 2  # a prefix is balanced
    assert null_specs(names, (2, 8), seed=0) == specs  # deterministic
    assert len({s.pair_id for s in specs}) == len(specs)


def test_store_manifest_and_both_orders(tmp_path):
    photo_dir = tmp_path / "photos"
    photo_dir.mkdir()
    for name, seed in (("a_1.png", 1), ("b_1.png", 2)):
        cv2.imwrite(str(photo_dir / name), _photo(1000, 800, seed).astype(np.uint8))
    specs = null_specs(["a_1.png", "b_1.png"], ratios=(3,), seed=0)
    entries = ensure_pairs(specs, tmp_path / "pairs", photo_dir)
    manifest = json.loads((tmp_path / "pairs" / "manifest.json").read_text())
    assert {e["pair_id"] for e in manifest} == {s.pair_id for s in specs}
    for e in manifest:
        assert set(e) >= {"kind", "photo", "high_photo", "ratio", "seed", "low_region",
                          "high_rect"}
        if e["kind"] == "same-photo":
            assert not rects_overlap(e["low_region"], e["high_rect"])
    low_file = tmp_path / "pairs" / entries[specs[0].pair_id]["low_file"]
    stamp = low_file.stat().st_mtime_ns
    ensure_pairs(specs, tmp_path / "pairs", photo_dir)  # the cache is re-used
    assert low_file.stat().st_mtime_ns == stamp
    tasks = make_tasks(entries.values(), tmp_path / "pairs", sift=True)
    assert len(tasks) == 2 * len(specs)
    for e in entries.values():
        assert sorted(t["order"] for t in tasks if t["pair_id"] == e["pair_id"]) == sorted(ORDERS)
    assert {t["first"] for t in tasks} == {"scalematch", "sift"}  # alternated


def _row(kind, order, claimed, sift_claimed=False, seconds=1.0, **evidence):
    return {"run_id": f"{kind}{order}{claimed}{seconds}", "kind": kind, "order": order,
            "matched": claimed, "false_claim": claimed, "seconds": seconds, "reason": "",
            "evidence": evidence,
            "sift": {"seconds": 0.5, "claimed": sift_claimed}}


def test_summary_counts_false_claims():
    rows = [_row("unrelated", "given", False, seconds=1.0, log10_nfa=3.0),
            _row("unrelated", "swapped", True, sift_claimed=True, seconds=3.0),
            _row("same-photo", "given", True, seconds=2.0, inliers=4.0),
            _row("same-photo", "swapped", False, seconds=4.0, log10_nfa="inf"),
            _row("same-photo", "swapped", False, seconds=5.0)]
    groups = {(g.kind, g.order): g for g in summarise(rows)}
    assert groups["unrelated", "given"].false_claims == 0
    assert groups["unrelated", "swapped"].false_claims == 1
    assert groups["same-photo", "all"].false_claims == 1
    assert groups["same-photo", "swapped"].runs == 2
    assert groups["all nulls", "all"].false_claims == 2
    assert groups["all nulls", "all"].runs == 5
    assert groups["all nulls", "all"].median_seconds == 3.0
    assert groups["all nulls", "all"].max_seconds == 5.0
    assert groups["all nulls", "all"].sift_claims == 1
    assert len(false_claims(rows)) == 2
    # a key missing from the evidence, or not finite, is skipped, not an error
    assert chart_keys(rows) == ["log10_nfa", "inliers"]
    assert percentiles(rows, ["log10_nfa"])["log10_nfa"]["n"] == 1


def test_chart_tolerates_missing_keys(tmp_path):
    pytest.importorskip("matplotlib")  # the chart needs the lab extra
    rows = [_row("unrelated", "given", False, log10_nfa=float(v)) for v in range(5)]
    true = [dict(_row("true", "given", False, log10_nfa=-50.0, inliers=30.0), success=True)]
    img = plot_distributions(rows, tmp_path / "c.png", true, size=(600, 400))
    assert img.shape == (400, 600, 3) and (tmp_path / "c.png").is_file()
    plot_distributions([], tmp_path / "empty.png", size=(300, 200))  # "no data", no crash


def test_resume_skips_done_rows(tmp_path):
    tasks = [{"run_id": f"p{k}|given|default", "k": k} for k in range(5)]
    rows_path = tmp_path / "rows.jsonl"
    with open(rows_path, "w") as f:  # two runs done, then a line cut by an interruption
        for k in (0, 3):
            f.write(json.dumps({"run_id": f"p{k}|given|default", "done_before": True}) + "\n")
        f.write('{"run_id": "p4|giv')
    ran = []

    def fake(task):
        ran.append(task["k"])
        return {"run_id": task["run_id"], "false_claim": False}

    rows = execute(tasks, rows_path, jobs=1, run=fake)
    assert ran == [1, 2, 4]
    assert len(rows) == 5 and len(load_rows(rows_path)) == 5
    assert execute(tasks, rows_path, jobs=1, run=fake) and ran == [1, 2, 4]  # nothing left


def test_lab_lists_the_command():
    from scalematch.lab.cli import lab

    result = CliRunner().invoke(lab, ["nulls", "--help"])
    assert result.exit_code == 0 and "--true-rows" in result.output


@pytest.mark.shared
def test_a_fixed_sample_end_to_end_makes_no_false_claim(shared_dir, tmp_path):
    pytest.importorskip("matplotlib")  # the page's chart needs the lab extra
    report = run_nulls(shared=shared_dir, out_dir=tmp_path, limit=3, seed=0)
    assert len(report.rows) == 6  # 3 pairs (2 unrelated, 1 same-photo), both orders
    assert {r["kind"] for r in report.rows} == set(KINDS)
    assert {r["order"] for r in report.rows} == set(ORDERS)
    assert not false_claims(report.rows), false_claims(report.rows)
    assert all(not r["reason"].startswith("error") for r in report.rows)
    page = write_nulls_doc(report, tmp_path / "docs" / "NULLS.md")
    assert (page.parent / "nulls.png").is_file() and "False claims: 0" in page.read_text()


def _report(tmp_path, mode: str, text: str):
    """A NullReport of ``mode`` with every setting the page names, a chart, and ``text``."""
    from scalematch.lab.nulls import NullReport

    chart = tmp_path / f"nulls_{mode}.png"
    cv2.imwrite(str(chart), np.zeros((4, 4), np.uint8))
    settings = {"command": f"scalematch lab nulls --mode {mode}", "date": "today", "commit": "abc",
                "run_commits": {"abc": 2}, "machine": "m", "load_average_at_start": 0.5,
                "python": "3", "opencv": "5", "numpy": "2", "jobs": 1, "mode": mode, "seed": 0,
                "ratios": (2,), "photos": ["a.jpg"], "pairs": 1, "runs_planned": 2,
                "sift": False, "keys_recorded": ["inliers"]}
    return NullReport(rows=({}, {}), true_rows=(), groups=(), stats={}, settings=settings,
                      rows_path=tmp_path / "rows.jsonl", chart_path=chart, text=text)


def test_the_page_gets_only_its_modes_section_and_chart(tmp_path):
    from scalematch.lab.nulls import doc_section
    from scalematch.lab.realpairs import markers

    begin, end = markers(*doc_section("no-views"))
    assert begin == ("<!-- nulls no-views: begin (written by scalematch lab nulls --mode "
                     "no-views) -->") and end == "<!-- nulls no-views: end -->"
    page = tmp_path / "docs" / "NULLS.md"
    page.parent.mkdir()
    default_begin, default_end = markers(*doc_section("default"))
    page.write_text(f"# The null set\n\nThe introduction.\n\n{default_begin}\n## Mode default\n"
                    f"\nold default table\n{default_end}\n\n{begin}\n## Mode no-views\n\n"
                    f"old no-views table\n{end}\n\nA closing line.\n")
    write_nulls_doc(_report(tmp_path, "no-views", "new no-views table"), page)
    text = page.read_text()
    assert text.startswith("# The null set\n\nThe introduction.\n\n")
    assert "old default table" in text and "A closing line." in text
    assert "old no-views table" not in text and text.count("new no-views table") == 1
    assert text.index(default_end) < text.index(begin) < text.index("new no-views") < text.index(
        end) < text.index("A closing line.")
    assert text.count("## Mode no-views") == 1 and "](nulls-no-views.png)" in text
    assert (page.parent / "nulls-no-views.png").is_file()
    assert not (page.parent / "nulls.png").exists()
    # a mode without a section yet is appended; the default's chart is nulls.png
    write_nulls_doc(_report(tmp_path, "paper", "paper table"), page)
    write_nulls_doc(_report(tmp_path, "default", "new default table"), page)
    text = page.read_text()
    assert "old default table" not in text and "new no-views table" in text
    assert text.index("A closing line.") < text.index("<!-- nulls paper: begin") < text.index(
        "paper table") < text.index("<!-- nulls paper: end -->")
    assert "](nulls.png)" in text and (page.parent / "nulls.png").is_file()
    assert (page.parent / "nulls-paper.png").is_file()


def test_a_new_page_gets_a_title_and_the_modes_section(tmp_path):
    page = write_nulls_doc(_report(tmp_path, "default", "the table"),
                           tmp_path / "docs" / "NULLS.md")
    text = page.read_text()
    assert text.startswith("# The null set: pairs with no answer\n\n<!-- nulls default: begin")
    assert text.rstrip().endswith("<!-- nulls default: end -->") and "the table" in text


def test_footprint_ncc_tells_the_right_placement_from_a_wrong_one():
    from scalematch.geometry import similarity_matrix
    from scalematch.lab.nulls import footprint_ncc

    high = _photo(320, 240, 5)
    t = similarity_matrix(0.25, 30.0, 60.0, 20.0)  # high px -> low px
    blurred = cv2.GaussianBlur(high, (0, 0), 0.5 * np.sqrt(15.0))
    low = cv2.warpAffine(blurred, t, (200, 160), flags=cv2.INTER_LINEAR)
    assert footprint_ncc(low, high, t) > 0.95
    assert abs(footprint_ncc(low, high, similarity_matrix(0.25, 120.0, 90.0, 60.0))) < 0.5


def test_false_claim_figure_shows_each_claimed_pair_once(tmp_path):
    from scalematch.lab.nulls import false_claim_figure

    photo_dir = tmp_path / "photos"
    photo_dir.mkdir()
    for name, seed in (("a_1.png", 1), ("b_1.png", 2)):
        cv2.imwrite(str(photo_dir / name), _photo(1000, 800, seed).astype(np.uint8))
    specs = null_specs(["a_1.png", "b_1.png"], ratios=(3,), seed=0)[:2]
    entries = ensure_pairs(specs, tmp_path / "pairs", photo_dir)
    claim = [[0.3, 0.0, 20.0], [0.0, 0.3, 10.0]]
    rows = [{"pair_id": s.pair_id, "order": o, "result_order": o, "false_claim": True,
             "matched": True, "transform": claim, "inliers": 7, "evidence": {"log10_nfa": -12.0}}
            for s in specs for o in ORDERS]
    img = false_claim_figure(rows, entries, tmp_path / "pairs", tmp_path / "fc.png", tile=100,
                             per_row=3)
    assert img is not None and (tmp_path / "fc.png").is_file()
    assert img.shape[1] == 3 * (2 * 100 + 6 + 16)  # two pairs in a row of three cells
    assert false_claim_figure(rows[:0], entries, tmp_path / "pairs", tmp_path / "x.png") is None


def test_a_claimed_fundamental_matrix_gets_no_footprint_figures(tmp_path):
    """A fundamental matrix maps a point to a line: the recorder neither warps the image by it
    (footprint NCC) nor draws its footprint, where a claimed similarity gets both."""
    from scalematch.lab.nulls import add_footprint_ncc

    rng = np.random.default_rng(0)
    img = (rng.uniform(0, 255, (60, 80))).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "low.png"), img)
    cv2.imwrite(str(tmp_path / "high.png"), img)
    entries = {"p": {"low_file": "low.png", "high_file": "high.png"}}
    f_row = {"pair_id": "p", "matched": True, "model": "fundamental", "order": "given",
             "transform": [[0.0, 0, 0], [0, 0, -1], [0, 1, 0]]}
    s_row = {"pair_id": "p", "matched": True, "model": "similarity", "order": "given",
             "transform": [[1.0, 0, 0], [0, 1.0, 0]]}
    add_footprint_ncc([f_row, s_row], entries, tmp_path)
    assert "footprint_ncc" not in f_row
    assert s_row["footprint_ncc"] == pytest.approx(1.0, abs=1e-6)
