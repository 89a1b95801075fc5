"""The fundamental-matrix benchmark on the ef pairs (``scalematch.lab.efpairs``): the score on
two cameras of known geometry, scalematch's F turned to the A -> B convention, the reader, and
one real pair of ../shared/data/ef (skipped when absent)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scalematch.lab.efpairs import (EfPair, Run, a_to_b, coarser_of, ef_folder,
                                    epipolar_distances, load_pair, markdown, read_points, row_of,
                                    run_scalematch, symmetric_epipolar_error)
from scalematch.result import Direction


def _camera(f: float, yaw_deg: float, centre) -> np.ndarray:
    """P = K [R | -R C]: focal ``f`` px, principal point (320, 240), turned by ``yaw`` about y."""
    k = np.array([[f, 0, 320], [0, f, 240], [0, 0, 1.0]])
    a = math.radians(yaw_deg)
    r = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    return k @ np.hstack([r, -r @ np.reshape(centre, (3, 1))])


def _fundamental(p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """F with x2^T F x1 = 0 from two cameras (Hartley & Zisserman, eq. 9.1: [e2]x P2 P1^+)."""
    c1 = np.linalg.svd(p1)[2][-1]
    e2 = p2 @ c1
    ex = np.array([[0, -e2[2], e2[1]], [e2[2], 0, -e2[0]], [-e2[1], e2[0], 0]])
    return ex @ p2 @ np.linalg.pinv(p1)


def _project(p: np.ndarray, x: np.ndarray) -> np.ndarray:
    h = np.hstack([x, np.ones((len(x), 1))]) @ p.T
    return h[:, :2] / h[:, 2:]


#: Camera A at the origin, camera B 1 unit to the right, turned by 10 degrees, a longer focal
#: (a zoom of 2): a general two-view geometry
P_A = _camera(500.0, 0.0, [0, 0, 0])
P_B = _camera(1000.0, -10.0, [1.0, 0.1, 0.2])
SCENE = np.random.default_rng(0).uniform([-2, -1.5, 6], [2, 1.5, 10], (20, 3))  # depths 6-10
POINTS = np.hstack([_project(P_A, SCENE), _project(P_B, SCENE)])  # x_A, y_A, x_B, y_B
F_AB = _fundamental(P_A, P_B)


def test_points_of_the_scene_lie_on_their_epipolar_lines():
    assert symmetric_epipolar_error(F_AB, POINTS) < 1e-6
    # the score does not depend on F's scale or sign
    assert symmetric_epipolar_error(-3e4 * F_AB, POINTS) < 1e-6
    # the wrong convention (x_A^T F x_B = 0) is far off
    assert symmetric_epipolar_error(F_AB.T, POINTS) > 10


def test_a_point_moved_across_its_epipolar_line_is_that_far_from_it():
    pts = POINTS.copy()
    line = F_AB @ np.append(pts[0, :2], 1.0)  # the epipolar line of x_A in B
    normal = line[:2] / np.hypot(*line[:2])
    pts[0, 2:] += 2.5 * normal  # x_B moved 2.5 px across its line
    d = epipolar_distances(F_AB, pts)
    assert d[0, 0] == pytest.approx(2.5, abs=1e-6)
    assert d[0, 1] > 0 and np.all(d[1:] < 1e-6)
    assert symmetric_epipolar_error(F_AB, pts) == pytest.approx(d[0].sum() / (2 * len(pts)))
    assert symmetric_epipolar_error(None, pts) == math.inf  # no F: no claim


@pytest.mark.parametrize("a_first", [True, False])
@pytest.mark.parametrize("order", [Direction.GIVEN, Direction.SWAPPED])
def test_scalematch_f_is_turned_to_a_to_b(a_first, order):
    # scalematch's F: x_coarser^T F x_finer = 0, the coarser image being the first given when
    # the order is GIVEN, the second when SWAPPED (result.py)
    coarser_is_first = order is Direction.GIVEN
    coarser_is_a = coarser_is_first == a_first
    p_fine, p_coarse = (P_B, P_A) if coarser_is_a else (P_A, P_B)
    f_scalematch = _fundamental(p_fine, p_coarse)
    f = a_to_b(f_scalematch, order, a_first)
    assert symmetric_epipolar_error(f, POINTS) < 1e-6
    assert coarser_of(order, a_first) == ("A" if coarser_is_a else "B")
    assert a_to_b(f_scalematch, str(order), a_first).tolist() == f.tolist()  # as in JSON


def test_read_points_skips_comments_and_checks_the_columns(tmp_path):
    path = tmp_path / "x_points.txt"
    path.write_text("# x_A y_A x_B y_B: clicked\n1 2 3 4\n\n  # another comment\n5 6.5 7 8e1\n")
    pts = read_points(path)
    assert pts.dtype == np.float64 and pts.tolist() == [[1, 2, 3, 4], [5, 6.5, 7, 80]]
    path.write_text("1 2 3\n")
    with pytest.raises(ValueError, match="four numbers"):
        read_points(path)
    path.write_text("# nothing\n")
    with pytest.raises(ValueError, match="no point"):
        read_points(path)


def test_rows_and_table_of_a_synthetic_run():
    pair = EfPair("synthetic", np.zeros((2, 2)), np.zeros((2, 2)), POINTS)
    rows = [row_of(pair, "A,B", Run("scalematch", F_AB, True, 50, 1.0)),
            row_of(pair, "A,B", Run("plane", None, True, 40, 1.0, parallax=True)),
            row_of(pair, "A,B", Run("sift-magsac", F_AB.T, True, 30, 0.5, matches=60))]
    assert rows[0]["solved"] and not rows[0]["wrong"]
    assert math.isnan(rows[1]["error_px"]) and not rows[1]["solved"] and not rows[1]["wrong"]
    assert rows[2]["wrong"] and not rows[2]["solved"]
    text = markdown(rows, {"command": "test"})
    assert "| synthetic | A,B | 0.00 | 50 | 1.0 | yes | yes | 40 |" in text
    assert "| sift-magsac | 1 | 1 | 0 | - | 1 | - | 0.5 |" in text


@pytest.mark.shared
def test_a_real_ef_pair_given_b_first():
    folder = ef_folder()
    if folder is None or not (folder / "booksh_points.txt").is_file():
        pytest.skip("../shared/data/ef is absent")
    pair = load_pair(folder, "booksh")
    assert pair.a.ndim == 2 and pair.points.shape == (10, 4)
    run = run_scalematch(pair, a_first=False)  # B given first (measured: answered swapped)
    err = symmetric_epipolar_error(run.f, pair.points)
    assert run.claimed and err < 3.0, f"{run.reason or f'{err:.2f} px'}"  # measured 0.94 px


def test_docstring_examples():
    import doctest

    import scalematch.lab.efpairs as module

    result = doctest.testmod(module)
    assert result.failed == 0 and result.attempted >= 5
