"""The benchmark runner end to end on a tiny run (needs ../shared; skipped when absent), and
what a rewrite of the page keeps."""

from __future__ import annotations

import csv

import pytest

from scalematch.lab.bench import _real_pairs_sections, run_benchmark, write_benchmarks_doc
from scalematch.lab.realpairs import MARK_BEGIN, MARK_END, markers, write_section


def test_tiny_benchmark_run_writes_its_outputs(shared_dir, tmp_path):
    pytest.importorskip("matplotlib")  # the plot needs the lab extra
    # the first four photos (sorted) are one scene; the fifth gives unrelated pairs a partner
    report = run_benchmark(shared=shared_dir, out_dir=tmp_path / "out", ratios=(4,), photos=5,
                           seed=0, methods=("scalematch", "sift"), unrelated=2, boat=False,
                           large=False, batch=False, log=lambda _: None)
    assert not report.skipped
    rows = list(csv.DictReader(open(report.csv_path)))
    synthetic = [r for r in rows if r["kind"] == "synthetic"]
    assert len(synthetic) == 5 * 2  # five photos, two methods, one ratio
    # both methods recover these textured x4 pairs (EVALUATION.md success: error < 3 px)
    assert all(r["success"] == "True" for r in synthetic), synthetic
    unrelated = [r for r in rows if r["kind"] == "unrelated" and r["method"] == "scalematch"]
    assert unrelated and all(r["claimed"] == "False" for r in unrelated)
    assert report.plot_path.is_file() and "scalematch" in report.table
    page = write_benchmarks_doc(report, tmp_path / "docs" / "TINY.md")
    assert (page.parent / "tiny.png").is_file()
    assert "![success rate against ratio](tiny.png)" in page.read_text()
    # the sections of `scalematch lab real-pairs` (another command's figures) survive a re-run
    write_section(page, "## Real pairs\n\n| a table |\n")
    write_section(page, "## Realistic\n\n| b table |\n", "realistic")
    write_benchmarks_doc(report, page)
    text = page.read_text()
    assert text.count("## Real pairs") == 1 and "| a table |" in text
    assert text.count("## Realistic") == 1 and "| b table |" in text
    assert text.index("Photos: ") < text.index(MARK_BEGIN) < text.index(MARK_END)
    assert text.index(MARK_END) < text.index(markers("realistic")[0])


def test_a_rewritten_page_keeps_the_real_and_the_realistic_pairs_sections(tmp_path):
    """What ``make bench`` keeps of docs/results/BENCHMARKS.md: the blocks that ``scalematch lab
    real-pairs`` wrote (the real pairs, and the realistic pairs of ``--sets realistic``), each
    with its markers, in the page's order; nothing else of the old page."""
    page = tmp_path / "BENCHMARKS.md"
    assert _real_pairs_sections(page) == ""
    page.write_text("# Benchmarks\n\nold tables\n")
    assert _real_pairs_sections(page) == ""
    write_section(page, "## Realistic\n\n| b table |\n", "realistic")
    write_section(page, "## Real pairs\n\n| a table |\n")
    kept = _real_pairs_sections(page)
    begin, end = markers("realistic")
    assert "old tables" not in kept and "# Benchmarks" not in kept
    assert kept.index(begin) < kept.index("| b table |") < kept.index(end) < kept.index(
        MARK_BEGIN) < kept.index("| a table |") < kept.index(MARK_END)
    assert kept.startswith("\n" + begin) and kept.endswith(MARK_END + "\n")
    # a section whose end marker is missing is not kept
    page.write_text(page.read_text().replace(end, ""))
    assert begin not in _real_pairs_sections(page) and MARK_BEGIN in _real_pairs_sections(page)


def test_pair_by_pair_names_every_pair_a_peer_solves_and_scalematch_misses():
    from scalematch.lab.bench import pair_by_pair

    row = lambda m, src, r, ok: dict(method=m, kind="synthetic", source=src, ratio=r, success=ok)
    rows = [row("scalematch", "a.jpg", 2.0, True), row("sift", "a.jpg", 2.0, True),
            row("scalematch", "b.jpg", 8.0, False), row("sift", "b.jpg", 8.0, True),
            row("scalematch", "c.jpg", 16.0, True), row("sift", "c.jpg", 16.0, False)]
    text = pair_by_pair(rows, ["scalematch", "sift"])
    assert "| sift | 1: b.jpg x8 | 1 |" in text
    assert pair_by_pair(rows, ["sift"]) == ""
