"""The real-pair benchmark's judging: a transform is turned to the finer -> coarser direction."""

from __future__ import annotations

import numpy as np

from scalematch.geometry import similarity_matrix
from scalematch.lab.realpairs import Pair, canonical, pair_error, write_section

TRUTH = np.vstack([similarity_matrix(0.5, 30.0, 40.0, 20.0), [0.0, 0.0, 1.0]])  # finer -> coarser
FINE = np.zeros((120, 160), np.float32)
COARSE = np.zeros((200, 260), np.float32)


def _pair(swapped: bool) -> Pair:
    low, high = (FINE, COARSE) if swapped else (COARSE, FINE)
    return Pair("test", "p", low, high, TRUTH, swapped, "homography", 2.0)


def test_a_transform_in_either_direction_is_judged_the_same_way():
    inv = np.linalg.inv(TRUTH)
    # given in order: a peer maps high (finer) -> low (coarser), the truth's direction
    assert pair_error(_pair(False), canonical(_pair(False), TRUTH, True)) < 1e-9
    # swapped: a peer maps the second image given (coarser) into the first (finer): inverted
    assert pair_error(_pair(True), canonical(_pair(True), inv, True)) < 1e-9
    # scalematch says it answered finer -> coarser on a swapped pair: kept as it is
    assert pair_error(_pair(True), canonical(_pair(True), TRUTH, False)) < 1e-9
    # a transform pointing the wrong way is an error, not a success
    assert pair_error(_pair(True), canonical(_pair(True), TRUTH, True)) > 10
    assert canonical(_pair(False), None, True) is None


def test_write_section_replaces_only_its_own_block(tmp_path):
    doc = tmp_path / "B.md"
    doc.write_text("# Benchmarks\n\nkept text\n")
    write_section(doc, "first\n")
    write_section(doc, "second\n")
    text = doc.read_text()
    assert text.startswith("# Benchmarks\n\nkept text\n") and "second" in text
    assert "first" not in text and text.count("real-pairs: begin") == 1


def test_the_tables_by_tilt_and_by_spread_follow_the_sets_run():
    """by_tilt and markdown: a table per family of sets run, labelled t or spread."""
    from scalematch.lab.realpairs import by_tilt, markdown, summarise

    rows = [{"set": s, "method": "scalematch", "pair": f"p{k}", "tilt": t, "success": k % 2 == 0,
             "claimed": True, "error_px": 0.5, "seconds": 1.0, "false_claim": False,
             "ratio": 2.0}
            for k, (s, t) in enumerate([("perspective", 4.0), ("perspective", 4.0),
                                        ("perspective-swapped", 8.0), ("steep", 8.0)])]
    tilts = by_tilt(rows)
    assert ("perspective", "scalematch", 4.0, 1, 2) in tilts
    assert ("perspective-swapped", "scalematch", 8.0, 1, 1) in tilts
    text = markdown(summarise(rows), tilts, [])
    assert "| set | method | spread = 4 | spread = 8 |" in text
    assert "| perspective | scalematch | 1/2 | - |" in text
    assert "| steep | scalematch | - | 0/1 |" in text and "Tilted pairs" not in text


def test_an_unknown_set_is_a_usage_error():
    from click.testing import CliRunner

    from scalematch.lab.realpairs import real_pairs_command

    result = CliRunner().invoke(real_pairs_command, ["--sets", "tilted,sideways",
                                                     "--shared", "."])
    assert result.exit_code == 2 and "unknown set 'sideways'" in result.output
