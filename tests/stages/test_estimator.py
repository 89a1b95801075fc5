"""Robust estimation (estimator.py): known transforms recovered among outliers."""

from __future__ import annotations

import numpy as np
import pytest

from scalematch.geometry import apply, similarity_matrix
from scalematch.stages.estimator import RansacParams, estimate, residuals


def _data(t, n_in=60, n_out=140, noise=0.3, seed=0):
    rng = np.random.default_rng(seed)
    src = rng.uniform(0, 640, (n_in + n_out, 2))
    dst = apply(t, src) + rng.normal(0, noise, (n_in + n_out, 2))
    dst[n_in:] = rng.uniform(0, 1024, (n_out, 2))  # 70 % outliers
    return src, dst


def test_similarity_among_outliers():
    t = similarity_matrix(0.2, 37.0, 300.0, 150.0)
    src, dst = _data(t)
    est = estimate("similarity", src, dst, seed=1)
    assert est.inliers[:60].mean() >= 0.95 and est.inliers[60:].sum() <= 2
    g = np.array([[0, 0], [639, 0], [639, 479], [0, 479]], float)
    assert np.abs(apply(est.transform, g) - apply(t, g)).max() < 0.5


@pytest.mark.parametrize("model", ["affine", "homography"])
def test_affine_and_homography(model):
    t = np.array([[0.25, 0.05, 100.0], [-0.03, 0.22, 80.0], [1e-5, 2e-5, 1.0]])
    if model == "affine":
        t = t[:2]
    src, dst = _data(t, seed=2)
    est = estimate(model, src, dst, seed=1)
    assert est.transform.shape == ((2, 3) if model == "affine" else (3, 3))
    assert est.inliers[:60].mean() >= 0.95
    assert np.median(residuals(model, est.transform, src[:60], dst[:60])) < 0.6


def test_fundamental_epipolar_residuals_small_on_inliers():
    rng = np.random.default_rng(3)
    x = rng.uniform(-5, 5, (80, 3)) + [0, 0, 20]  # 3-D points in front of two cameras
    k = np.array([[500, 0, 320], [0, 500, 240], [0, 0, 1.0]])
    p1 = (k @ x.T).T
    r = np.array([[0.98, -0.17, 0], [0.17, 0.98, 0], [0, 0, 1.0]])
    p2 = (k @ (r @ x.T + np.array([[2.0], [0.3], [0.0]]))).T
    src, dst = p1[:, :2] / p1[:, 2:], p2[:, :2] / p2[:, 2:]
    est = estimate("fundamental", src, dst, seed=0)
    assert est.transform.shape == (3, 3)
    assert np.median(residuals("fundamental", est.transform, src, dst)) < 0.5


def test_fundamental_among_noise_and_outliers():
    """1 px of noise on 120 true pairs and 60 random ones: the true pairs are the inliers, and
    the noise-free points lie within the noise (1 px) of the estimated epipolar lines."""
    rng = np.random.default_rng(5)
    x = rng.uniform(-6, 6, (120, 3)) + [0, 0, 25]
    k = np.array([[600, 0, 320], [0, 600, 240], [0, 0, 1.0]])
    c, s_ = np.cos(0.2), np.sin(0.2)
    r = np.array([[c, 0, s_], [0, 1, 0], [-s_, 0, c]])  # turned about the vertical axis
    p1 = (k @ x.T).T
    p2 = (k @ (r @ x.T + np.array([[3.0], [0.2], [0.5]]))).T
    src, dst = p1[:, :2] / p1[:, 2:], p2[:, :2] / p2[:, 2:]
    noisy_src = np.vstack([src + rng.normal(0, 1, src.shape), rng.uniform(0, 640, (60, 2))])
    noisy_dst = np.vstack([dst + rng.normal(0, 1, dst.shape), rng.uniform(0, 640, (60, 2))])
    est = estimate("fundamental", noisy_src, noisy_dst, seed=0)
    assert est.inliers[:120].mean() >= 0.9 and est.inliers[120:].mean() <= 0.2
    # MAGSAC++'s own weighted fit, kept (no least-squares refit on the inliers): within half the
    # noise of the noise-free points
    assert np.mean(residuals("fundamental", est.transform, src, dst)) < 0.5


def test_fundamental_falls_back_to_ransac_where_usac_fails(monkeypatch):
    """OpenCV's USAC raised an assertion on one null pair: the fit then uses OpenCV's RANSAC."""
    import cv2

    real = cv2.findFundamentalMat

    def usac_fails(src, dst, method, *args):
        if method == cv2.USAC_MAGSAC:
            raise cv2.error("empty model")
        return real(src, dst, method, *args)

    rng = np.random.default_rng(3)
    x = rng.uniform(-5, 5, (80, 3)) + [0, 0, 20]
    k = np.array([[500, 0, 320], [0, 500, 240], [0, 0, 1.0]])
    p1 = (k @ x.T).T
    p2 = (k @ (x.T + np.array([[2.0], [0.3], [0.0]]))).T
    src, dst = p1[:, :2] / p1[:, 2:], p2[:, :2] / p2[:, 2:]
    monkeypatch.setattr(cv2, "findFundamentalMat", usac_fails)
    est = estimate("fundamental", src, dst, seed=0)
    assert est.transform is not None and est.n_inliers >= 76


def test_fundamental_residual_is_the_larger_one_sided_distance_to_the_epipolar_lines():
    """A sideways translation: the epipolar lines are the rows (F = [e]_x, e = (1, 0, 0)). A
    pair 3 rows apart lies 3 px from its line in each image (the Sampson distance would say
    3 / sqrt(2): less than the band of chance the a-contrario test counts)."""
    f = np.array([[0.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    src = np.array([[10.0, 20.0], [50.0, 7.0]])
    dst = np.array([[30.0, 23.0], [-4.0, 7.0]])
    np.testing.assert_allclose(residuals("fundamental", f, src, dst), [3.0, 0.0], atol=1e-9)


def test_too_few_points_is_an_empty_estimate():
    est = estimate("homography", np.zeros((3, 2)), np.zeros((3, 2)))
    assert est.transform is None and est.n_inliers == 0


def test_same_seed_same_answer():
    src, dst = _data(similarity_matrix(0.5, -120.0, 10.0, 20.0), seed=4)
    a = estimate("similarity", src, dst, RansacParams(), seed=7)
    b = estimate("similarity", src, dst, RansacParams(), seed=7)
    assert np.array_equal(a.transform, b.transform) and np.array_equal(a.inliers, b.inliers)


def test_the_model_records():
    """One record per model: what the pipeline, the decision and the pictures ask of it."""
    from scalematch.config import MODELS as NAMES
    from scalematch.stages.estimator import MODELS, model_of

    assert NAMES == tuple(MODELS) == ("similarity", "affine", "homography", "fundamental")
    assert [m.min_sample for m in MODELS.values()] == [2, 3, 4, 8]
    assert [m.name for m in MODELS.values() if not m.has_ratio] == ["fundamental"]
    # the chance area: a disc of radius 3 px around a predicted point, a 6 px band along a line
    assert model_of("affine").chance_area(3.0, (30, 40)) == pytest.approx(np.pi * 9)
    assert model_of("fundamental").chance_area(3.0, (30, 40)) == pytest.approx(6.0 * 50)
    with pytest.raises(ValueError, match="unknown model 'shear'; one of similarity"):
        model_of("shear")


def test_no_product_module_special_cases_a_model_by_name():
    """Model differences are attributes of the record (stages/estimator.py), not string tests."""
    from pathlib import Path

    import scalematch

    root = Path(scalematch.__file__).parent
    for path in root.rglob("*.py"):
        if "lab" in path.relative_to(root).parts or path.name == "estimator.py":
            continue
        assert '== "fundamental"' not in path.read_text(), path
        assert '!= "fundamental"' not in path.read_text(), path


def test_each_model_carries_its_parts_and_its_change_of_pixels():
    """A point map has a ratio, a rotation, a translation and a footprint, and is carried into
    other pixels of both images by composition; a fundamental matrix has none of them, and is
    carried so that the pairs it holds still hold in the new pixels."""
    import math

    from scalematch.stages.estimator import model_of

    t = similarity_matrix(0.25, 30.0, 5.0, -2.0)  # finer px -> coarser px
    ratio, angle, _ = model_of("similarity").parts(t, np.array([[7.0, 9.0]]))
    assert ratio == pytest.approx(4.0) and angle == pytest.approx(30.0)
    assert all(math.isnan(v) for v in model_of("fundamental").parts(np.eye(3))[:2])
    s_fine = similarity_matrix(0.5, 0.0, 0.25, 0.25)
    s_coarse = similarity_matrix(1 / 3, 0.0, 1.0, 1.0)
    xy = np.array([[10.0, 20.0], [-4.0, 7.5]])
    carried = model_of("similarity").carried(t, s_fine, s_coarse)
    assert apply(carried, apply(s_fine, xy)) == pytest.approx(apply(s_coarse, apply(t, xy)))
    f = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # y_coarser = y_finer
    fine, coarse = np.array([[3.0, 8.0], [50.0, 2.0]]), np.array([[40.0, 8.0], [1.0, 2.0]])
    assert residuals("fundamental", f, fine, coarse) == pytest.approx([0.0, 0.0])
    moved = model_of("fundamental").carried(f, s_fine, s_coarse)
    assert residuals("fundamental", moved, apply(s_fine, fine), apply(s_coarse, coarse)) == \
        pytest.approx([0.0, 0.0], abs=1e-9)
    swapped = apply(s_coarse, coarse[::-1])  # each coarser point with the other's finer one
    assert residuals("fundamental", moved, apply(s_fine, fine), swapped).min() > 1
    corners = model_of("similarity").footprint(similarity_matrix(0.5, 0.0), (40, 60))
    assert corners.tolist() == [[-0.25, -0.25], [29.75, -0.25], [29.75, 19.75], [-0.25, 19.75]]
    assert model_of("fundamental").footprint(f, (40, 60)) is None
    # accepted: a point map stands as fitted; a matrix of too few pairs for its refinement too
    assert model_of("affine").refined(t, np.zeros((20, 4))) is t
    assert model_of("fundamental").refined(f, np.zeros((7, 4))) is f
