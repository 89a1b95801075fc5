"""result: the frozen MatchResult."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import scalematch
from scalematch.cli import cli
from scalematch.config import Config
from scalematch.result import Direction, Evidence, MatchResult, ScaleRow, dumps

ROOT = Path(__file__).resolve().parents[1]


def hand_result(t=None) -> MatchResult:
    """A matched similarity result built by hand (ratio 2, no rotation, shift (5, -3))."""
    t = np.array([[0.5, 0.0, 5.0], [0.0, 0.5, -3.0]]) if t is None else t
    xy_high = np.array([[10.0, 20.0], [30.0, 40.0], [50.0, 10.0]])
    inliers = np.hstack([xy_high, xy_high @ t[:, :2].T + t[:, 2]])
    rows = (ScaleRow(s=1.0, ratio=float("nan"), points=10, initial=0, kept=0, inliers=0,
                     outlier_pct=100.0),
            ScaleRow(s=2.0, ratio=2.0, points=20, initial=4, kept=3, inliers=3, outlier_pct=25.0,
                     rotation_deg=0.0))
    return MatchResult(matched=True, reason="", model="similarity", transform=t,
                       resolution_ratio=2.0, rotation_deg=0.0, translation=(5.0, -3.0),
                       best_scale=2.0, inliers=inliers, scales=rows, timings={"total": 0.25},
                       config=Config(), evidence=Evidence(log10_nfa=-5.0))


def test_the_arrays_of_a_result_are_read_only_copies():
    t = np.array([[0.5, 0.0, 5.0], [0.0, 0.5, -3.0]])
    r = hand_result(t)
    for a in (r.transform, r.inliers):
        with pytest.raises(ValueError, match="read-only"):
            a[0, 0] = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.transform = None
    t[0, 0] = 9.0  # the caller's array stays writable and is not the result's
    assert r.transform[0, 0] == 0.5
    # a result without a transform (no match) still has a read-only (0, 4) inliers array
    none = dataclasses.replace(r, matched=False, transform=None, inliers=np.zeros((0, 4)))
    assert none.transform is None and none.n_inliers == 0 and not none.inliers.flags.writeable


def test_the_json_of_a_hand_built_result_has_plain_types_and_no_nan():
    d = hand_result().to_dict("low.png", "high.png", (100, 200), (400, 800))
    assert d["order"] == "given" and d["matched"] is True and d["reason"] is None
    assert d["transform"] == [[0.5, 0.0, 5.0], [0.0, 0.5, -3.0]]
    assert d["scales"][0]["ratio"] is None  # nan -> null
    assert d["low"] == {"path": "low.png", "width": 200, "height": 100,
                        "nodata": {"value": None, "share": 0.0}, "warning": None}
    text = hand_result().to_json("low.png", "high.png", (100, 200), (400, 800))
    assert text.endswith("}\n") and json.loads(text) == d
    assert "\n" not in hand_result().to_json("a", "b", (1, 1), (1, 1), indent=None).rstrip("\n")


def test_the_library_json_is_the_command_line_file(tmp_path):
    """``scalematch.match(...).to_json(...)`` is the CLI's --json file (but for the clock)."""
    low, high = str(ROOT / "data" / "demo_low.png"), str(ROOT / "data" / "demo_high.png")
    path = tmp_path / "r.json"
    run = CliRunner().invoke(cli, [low, high, "--json", str(path), "--quiet"])
    assert run.exit_code == 0, run.output
    file_text = path.read_text()
    from_file = json.loads(file_text)
    low_img, high_img = scalematch.read_grey(low), scalematch.read_grey(high)
    lib = scalematch.match(low_img, high_img).to_dict(low, high, low_img.shape, high_img.shape)
    lib["seconds"], lib["timings"] = from_file["seconds"], from_file["timings"]
    assert dumps(lib, indent=2) + "\n" == file_text


def test_to_dict_without_paths_or_sizes_writes_null_there():
    """Arrays matched in Python have no file to name: the record still comes, null there."""
    r = MatchResult(matched=False, model="similarity", reason="too few inliers")
    d = r.to_dict()
    assert d["low"] == d["high"] == {"path": None, "width": None, "height": None,
                                     "nodata": {"value": None, "share": 0.0}, "warning": None}
    assert json.loads(r.to_json())["matched"] is False


def test_an_images_warning_goes_with_its_record_whichever_the_order():
    """What the reading of the first image given warned of is in its own record: ``low``
    in the given order, ``high`` when the order is swapped."""
    said = ("a.jpg: the JPEG decoder says ...", "")
    given = hand_result().to_dict("a.jpg", "b.png", (100, 200), (400, 800), said)
    assert given["low"]["warning"] == said[0] and given["high"]["warning"] is None
    swapped = dataclasses.replace(hand_result(), order=Direction.SWAPPED)
    d = json.loads(swapped.to_json("a.jpg", "b.png", (100, 200), (400, 800), warnings=said))
    assert d["high"]["path"] == "a.jpg" and d["high"]["warning"] == said[0]
    assert d["low"]["warning"] is None


def test_the_json_of_a_fundamental_matrix_gives_its_epipoles_by_image():
    """A matrix whose finer epipole is (100, 50) and coarser one is at infinity along x: the
    JSON names them by image, as the order says which is the coarser; other answers give null."""
    from scalematch.geometry import epipoles
    from scalematch.result import Direction

    e_fine = np.array([100.0, 50.0, 1.0])
    skew = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # [(1, 0, 0)]_x
    a = np.array([[0.01, 0, 0], [0, 1, -50], [-0.01, 0, 1]])  # a e_fine = (1, 0, 0)
    f = skew @ a  # F e_fine = 0 and (1, 0, 0) F = 0
    assert np.allclose(f @ e_fine, 0)
    fine, coarse = epipoles(f)
    assert np.allclose(fine, e_fine) and np.allclose(coarse, [1, 0, 0])
    given = MatchResult(matched=True, model="fundamental", transform=f, inliers=np.zeros((0, 4)))
    assert given.to_dict()["epipoles"] == {"low": [1.0, 0.0, 0.0], "high": [100.0, 50.0, 1.0]}
    swapped = dataclasses.replace(given, order=Direction.SWAPPED)
    assert swapped.to_dict()["epipoles"] == {"low": [100.0, 50.0, 1.0], "high": [1.0, 0.0, 0.0]}
    plane = MatchResult(matched=True, model="similarity",
                        transform=np.array([[0.5, 0, 0], [0, 0.5, 0]]), inliers=np.zeros((0, 4)))
    assert plane.to_dict()["epipoles"] is None
