"""Descriptors (descriptors.py): local-jet invariants and oriented gradient histograms.

Known answers:

* the jet invariants of a cubic polynomial image against their closed form;
* exact invariance of ``jet_invariants`` to rotating the derivative tensors, to a grey-level gain
  and to a change of scale (derivatives of order n scale as k^-n, the jet's std as k);
* on a real photo (data/raccoon.jpg) and its copy rotated about the centre by 30, 90 and 137
  degrees (cv2.warpAffine, INTER_CUBIC), or re-lit by gain 0.7 and offset +20: the descriptors of
  the same points (detected in the photo, mapped by the known transform, kept away from the
  border) are close compared with those of different points, and the dominant orientations turn
  with the image;
* on the photo against a rotated, re-lit and noised 8-bit copy, with points detected in both:
  the nearest neighbour of a point is its true partner for a stated fraction of points.

Thresholds are set from measured values (written next to each) with headroom.

These tests found a bug, since fixed: ``L_jkl L_k L_l`` of v5 and v7 was computed with an
extra sum over the free index ``i`` (a factor ``L_x + L_y``), so v5 and v7 were neither rotation-
nor gain-invariant. The per-component tests below guard against its return.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from scalematch.geometry import apply, similarity_matrix
from scalematch.stages.descriptors import (JET_DIM, GradientParams, JetParams, describe_gradients,
                                           describe_jets, jet_invariants, local_jet)
from scalematch.stages.detector import HarrisParams, detect_one
from scalematch.stages.mahalanobis import load_covariance, whiten
from scalematch.stages.matcher import MatcherParams, match_descriptors
from scalematch.stages.scalespace import Level
from scalematch.stages import descriptors

NAMES = ("v2", "v3", "v4", "v5", "v6", "v7", "v8")
#: components not touched by the v5/v7 bug
FIVE = [0, 1, 2, 4, 6]


def _per_component():
    """One parameter per jet component; v5 and v7 are expected to fail (the bug above)."""
    return [pytest.param(c, id=NAMES[c],
                         marks=[])
            for c in range(JET_DIM)]


# --------------------------------------------------------------------------------------------
# Reference: the invariants written out component by component (module docstring of
# descriptors.py, Schmid & Mohr 1997), no einsum
# --------------------------------------------------------------------------------------------


def reference_invariants(l1, l2, l3, sigma):
    lx, ly = l1[:, 0], l1[:, 1]
    lxx, lxy, lyy = l2[:, 0, 0], l2[:, 0, 1], l2[:, 1, 1]
    lxxx, lxxy, lxyy, lyyy = l3[:, 0, 0, 0], l3[:, 0, 0, 1], l3[:, 0, 1, 1], l3[:, 1, 1, 1]
    v1 = lx * lx + ly * ly
    v2 = lx * lx * lxx + 2 * lx * ly * lxy + ly * ly * lyy
    v3 = lxx + lyy
    v4 = lxx * lxx + 2 * lxy * lxy + lyy * lyy
    tx = lxxx * lx * lx + 2 * lxxy * lx * ly + lxyy * ly * ly  # T_j = L_jkl L_k L_l
    ty = lxxy * lx * lx + 2 * lxyy * lx * ly + lyyy * ly * ly
    sx, sy = lxxx + lxyy, lxxy + lyyy  # S_j = L_jkk
    cross_t = lx * ty - ly * tx  # eps_ij L_i T_j with eps_xy = 1
    cross_s = lx * sy - ly * sx
    v5 = cross_t - cross_s * v1
    v6 = (sx * lx + sy * ly) * v1 - (lx * tx + ly * ty)
    v7 = -cross_t
    v8 = lx * tx + ly * ty
    g = np.sqrt(v1)
    s = sigma
    return np.stack([s * v2 / g ** 3, s * v3 / g, s * s * v4 / g ** 2, s * s * v5 / g ** 4,
                     s * s * v6 / g ** 4, s * s * v7 / g ** 4, s * s * v8 / g ** 4], axis=1)


def random_jets(n=50, seed=0):
    """Random derivative tensors (fully symmetric), gradients of 5-20 grey levels / px."""
    rng = np.random.default_rng(seed)
    ang = rng.uniform(0, 2 * np.pi, n)
    mag = rng.uniform(5, 20, n)
    l1 = np.stack([mag * np.cos(ang), mag * np.sin(ang)], axis=1)
    a, b, c = rng.normal(0, 3, (3, n))
    l2 = np.stack([np.stack([a, b], 1), np.stack([b, c], 1)], 1)
    t = rng.normal(0, 1, (4, n))  # xxx, xxy, xyy, yyy
    l3 = np.empty((n, 2, 2, 2))
    for i in range(2):
        for j in range(2):
            for k in range(2):
                l3[:, i, j, k] = t[i + j + k]
    return l1, l2, l3


def rotate_jets(l1, l2, l3, theta):
    r = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    return (np.einsum("ai,ni->na", r, l1), np.einsum("ai,bj,nij->nab", r, r, l2),
            np.einsum("ai,bj,ck,nijk->nabc", r, r, r, l3))


# --------------------------------------------------------------------------------------------
# Exact algebraic properties of jet_invariants
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("c", _per_component())
def test_jet_invariants_follow_the_formulas(c):
    l1, l2, l3 = random_jets()
    np.testing.assert_allclose(jet_invariants(l1, l2, l3, 2.0)[:, c],
                               reference_invariants(l1, l2, l3, 2.0)[:, c], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("c", _per_component())
def test_jet_invariants_are_unchanged_by_rotating_the_derivatives(c):
    l1, l2, l3 = random_jets()
    v = jet_invariants(l1, l2, l3, 2.0)[:, c]
    for theta in np.radians([30.0, 90.0, 137.0, -101.0]):
        vr = jet_invariants(*rotate_jets(l1, l2, l3, theta), 2.0)[:, c]
        np.testing.assert_allclose(vr, v, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("c", _per_component())
def test_jet_invariants_are_unchanged_by_a_gain(c):
    l1, l2, l3 = random_jets()  # |L1| >= 5 stays above the 0.5 floor after a gain of 0.3
    v = jet_invariants(l1, l2, l3, 2.0)[:, c]
    for gain in (0.3, 0.7, 1.3):
        np.testing.assert_allclose(jet_invariants(gain * l1, gain * l2, gain * l3, 2.0)[:, c], v,
                                   rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("c", _per_component())
def test_jet_invariants_are_unchanged_by_a_zoom_with_the_jet_scale(c):
    # the image zoomed out by k: derivatives of order n times k^n, the jet's std divided by k
    l1, l2, l3 = random_jets()
    v = jet_invariants(l1, l2, l3, 8.0)[:, c]
    k = 4.0
    np.testing.assert_allclose(jet_invariants(k * l1, k ** 2 * l2, k ** 3 * l3, 8.0 / k)[:, c], v,
                               rtol=1e-9, atol=1e-12)


def test_a_mirror_image_keeps_the_even_invariants():
    # x -> -x flips L_x, L_xy, L_xxx, L_xyy; v2, v3, v4, v6, v8 are unchanged (v5 and v7, built
    # with eps, change sign: covered by the formula test above)
    l1, l2, l3 = random_jets()
    m = np.diag([-1.0, 1.0])
    l1m, l2m, l3m = (np.einsum("ai,ni->na", m, l1), np.einsum("ai,bj,nij->nab", m, m, l2),
                     np.einsum("ai,bj,ck,nijk->nabc", m, m, m, l3))
    np.testing.assert_allclose(jet_invariants(l1m, l2m, l3m, 2.0)[:, FIVE],
                               jet_invariants(l1, l2, l3, 2.0)[:, FIVE], rtol=1e-9, atol=1e-12)


def test_a_vanishing_gradient_is_floored_not_divided_by_zero():
    l1, l2, l3 = random_jets(5)
    v = jet_invariants(np.zeros_like(l1), l2, l3, 2.0)
    assert np.all(np.isfinite(v))
    # with L1 = 0 and g floored at 0.5: v3 = sigma (L_xx + L_yy) / 0.5, the others are 0
    np.testing.assert_allclose(v[:, 1], 2.0 * (l2[:, 0, 0] + l2[:, 1, 1]) / 0.5, rtol=1e-12)
    np.testing.assert_allclose(v[:, [0, 3, 4, 5, 6]], 0.0, atol=1e-12)


# --------------------------------------------------------------------------------------------
# A cubic polynomial image: the jet in closed form
# --------------------------------------------------------------------------------------------

#: I(x, y) = d x + e y + a x^2 + b xy + c y^2 + f x^3 + g x^2 y + h x y^2 + k y^3 + 100,
#: (x, y) relative to the centre pixel (30, 30) of a 61x61 image (L_x + L_y is about 4.5, far
#: from 1, so that the v5/v7 bug shows here too)
POLY = dict(d=3.0, e=1.5, a=0.05, b=-0.08, c=0.03, f=0.002, g=-0.001, h=0.0015, k=0.0005)


def _cubic_image():
    y, x = np.mgrid[-30:31, -30:31].astype(np.float64)
    p = POLY
    img = (100 + p["d"] * x + p["e"] * y + p["a"] * x * x + p["b"] * x * y + p["c"] * y * y
           + p["f"] * x ** 3 + p["g"] * x * x * y + p["h"] * x * y * y + p["k"] * y ** 3)
    return img.astype(np.float32)


def _cubic_jet(sigma):
    """Closed form at the centre: G_sigma * I = I + sigma^2/2 Laplacian(I) for a cubic."""
    p = POLY
    l1 = np.array([[p["d"] + sigma ** 2 * (3 * p["f"] + p["h"]),
                    p["e"] + sigma ** 2 * (p["g"] + 3 * p["k"])]])
    l2 = np.array([[[2 * p["a"], p["b"]], [p["b"], 2 * p["c"]]]])
    t = [6 * p["f"], 2 * p["g"], 2 * p["h"], 6 * p["k"]]
    l3 = np.empty((1, 2, 2, 2))
    for i in range(2):
        for j in range(2):
            for k in range(2):
                l3[0, i, j, k] = t[i + j + k]
    return l1, l2, l3


def test_local_jet_of_a_cubic_image_is_its_closed_form():
    level = Level(1.0, 1.0, 0.0, _cubic_image())
    l1, l2, l3 = local_jet(level, np.array([[30.0, 30.0]]), 2.0)
    e1, e2, e3 = _cubic_jet(2.0)
    # measured: L1 relative error 3e-6 (the sigma^2 term through truncated kernels), L2 and L3
    # absolute error 5e-7 (float32 filtering of values ~100) on entries 0.002 .. 0.16
    np.testing.assert_allclose(l1, e1, rtol=1e-4)
    np.testing.assert_allclose(l2, e2, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(l3, e3, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("c", _per_component())
def test_describe_jets_of_a_cubic_image_is_its_closed_form(c):
    level = Level(1.0, 1.0, 0.0, _cubic_image())
    # at s = 1 the jet's std is JetParams.scale_factor * sigma~ = 2 px
    v = describe_jets(level, np.array([[30.0, 30.0]]), 2.0, JetParams())
    expected = reference_invariants(*_cubic_jet(2.0), 2.0)
    # measured relative error <= 1.5e-4 on v2, v3, v4, v6, v8
    np.testing.assert_allclose(v[:, c], expected[:, c], rtol=1e-3, atol=1e-6)


# --------------------------------------------------------------------------------------------
# A real photo and its rotated / re-lit copies, same points mapped by the known transform
# --------------------------------------------------------------------------------------------

MARGIN_PX = 30.0  #: points kept this far inside the largest disk that any rotation keeps inside


def _rotation_about_centre(shape, angle_deg):
    h, w = shape
    c = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    a = similarity_matrix(1.0, angle_deg)
    a[:, 2] = c - a[:, :2] @ c
    return a


def _warp(image, a):
    h, w = image.shape
    return cv2.warpAffine(image, a, (w, h), flags=cv2.INTER_CUBIC,
                          borderMode=cv2.BORDER_REFLECT_101)


@pytest.fixture(scope="module")
def photo(raccoon):
    """The photo, its points inside the central disk, their jets (whitened) and gradients."""
    h, w = raccoon.shape
    xy = detect_one(raccoon, 1.0, HarrisParams()).xy
    centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    xy = xy[np.linalg.norm(xy - centre, axis=1) < min(h, w) / 2.0 - MARGIN_PX]
    level = Level(1.0, 1.0, 0.0, raccoon)
    wh = load_covariance().whitening()
    jets = whiten(describe_jets(level, xy, HarrisParams().sigma_tilde), wh)
    grads = describe_gradients(level, xy, GradientParams())
    return dict(image=raccoon, xy=xy, jets=jets, grads=grads, whitening=wh)


def _jet_distances(photo, changed, a):
    """Whitened distances of true pairs, and of each point to a random other point."""
    mapped = apply(a, photo["xy"])
    jets = whiten(describe_jets(Level(1.0, 1.0, 0.0, changed), mapped,
                                HarrisParams().sigma_tilde), photo["whitening"])
    true = np.linalg.norm(photo["jets"] - jets, axis=1)
    n = len(true)
    other = (np.arange(n) + np.random.default_rng(0).integers(1, n, n)) % n  # never itself
    return true, np.linalg.norm(photo["jets"] - jets[other], axis=1)


def _gradient_pairs(photo, changed, a, angle_deg):
    """For each row of the photo, the copy's row of the same point whose orientation is nearest
    the expected one: (descriptor distance, orientation error in degrees, random distance)."""
    g0 = photo["grads"]
    g1 = describe_gradients(Level(1.0, 1.0, 0.0, changed), apply(a, photo["xy"]),
                            GradientParams())
    dist, err = np.full(len(g0), np.inf), np.full(len(g0), 180.0)
    for r in range(len(g0)):
        rows = np.nonzero(g1.index == g0.index[r])[0]
        if rows.size == 0:
            continue
        d_ang = np.angle(np.exp(1j * (g1.angle[rows] - g0.angle[r] - np.radians(angle_deg))))
        best = rows[np.argmin(np.abs(d_ang))]
        dist[r] = np.linalg.norm(g0.desc[r] - g1.desc[best])
        err[r] = np.degrees(np.abs(d_ang).min())
    other = np.random.default_rng(0).integers(0, len(g1), len(g0))
    keep = g1.index[other] != g0.index  # a different point
    rand = np.linalg.norm(g0.desc[keep] - g1.desc[other[keep]], axis=1)
    return dist, err, rand


def test_the_photo_gives_enough_points(photo):
    assert len(photo["xy"]) > 1500  # measured 2294 points inside the central disk


def test_gradient_descriptors_are_unit_vectors(photo):
    d = photo["grads"].desc
    assert d.shape[1] == 128 and d.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-4)
    assert np.all(d >= 0)
    # one row per dominant orientation: most points have one, some two or three
    counts = np.bincount(photo["grads"].index)
    assert 1.0 <= counts[counts > 0].mean() < 1.5  # measured 1.30 rows per point


#: angle: (median true / median random, fraction of true pairs under 1.0, 90th percentile)
#: measured 30: 0.033, 0.858, 1.20; 90: 0.037, 0.703, 2.05; 137: 0.065, 0.532, 3.03
JET_ROTATION = {30.0: (0.06, 0.75, 2.0), 90.0: (0.06, 0.6, 3.0), 137.0: (0.1, 0.45, 4.0)}


@pytest.mark.parametrize("angle", [30.0, 90.0, 137.0])
def test_jets_of_the_same_points_agree_under_rotation(photo, angle):
    a = _rotation_about_centre(photo["image"].shape, angle)
    true, rand = _jet_distances(photo, _warp(photo["image"], a), a)
    ratio_max, frac_min, p90_max = JET_ROTATION[angle]
    assert np.median(true) < ratio_max * np.median(rand)  # random pairs: median 14.0-14.1
    assert np.mean(true < 1.0) > frac_min
    assert np.quantile(true, 0.9) < p90_max


#: angle: (median distance, fraction under 0.3, fraction of orientations within 10 degrees)
#: measured 30: 0.143, 0.777, 0.755; 90: 1e-5, 0.986, 0.985; 137: 0.145, 0.770, 0.749;
#: random pairs of different points: median 0.80
GRADIENT_ROTATION = {30.0: (0.25, 0.65, 0.65), 90.0: (0.05, 0.95, 0.95),
                     137.0: (0.25, 0.65, 0.65)}


@pytest.mark.parametrize("angle", [30.0, 90.0, 137.0])
def test_gradient_descriptors_of_the_same_points_agree_under_rotation(photo, angle):
    a = _rotation_about_centre(photo["image"].shape, angle)
    dist, err, rand = _gradient_pairs(photo, _warp(photo["image"], a), a, angle)
    med_max, frac_min, orient_min = GRADIENT_ROTATION[angle]
    assert np.median(dist) < med_max
    assert np.median(rand) > 0.6  # measured 0.80
    assert np.mean(dist < 0.3) > frac_min
    # the dominant orientation turns with the image: median error measured 4.1 deg at 30 and
    # 137, 0 at 90 (an exact permutation of the pixels)
    assert np.mean(err < 10.0) > orient_min
    assert np.median(err) < 6.0


def test_jets_agree_under_gain_and_offset(photo):
    img = photo["image"]
    changed = (0.7 * img + 20.0).astype(np.float32)
    identity = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    true, rand = _jet_distances(photo, changed, identity)
    # measured: median 0.119 against 14.0 for random pairs, 99.2 % under 1, 90th pct 0.45; not
    # 0 because of the v5/v7 bug (they scale with the gain); v2, v3, v4, v6, v8 are exact:
    assert np.median(true) < 0.03 * np.median(rand)
    assert np.mean(true < 1.0) > 0.95
    level0, level1 = Level(1.0, 1.0, 0.0, img), Level(1.0, 1.0, 0.0, changed)
    raw0 = describe_jets(level0, photo["xy"], 2.0)
    raw1 = describe_jets(level1, photo["xy"], 2.0)
    g = np.linalg.norm(local_jet(level0, photo["xy"], 2.0)[0], axis=1)
    ok = 0.7 * g > 2 * JetParams().min_gradient  # the floor is not reached in either image
    assert ok.mean() > 0.95  # measured 98.4 %
    # measured max absolute difference 1.1e-4 (float32 filtering)
    np.testing.assert_allclose(raw1[ok], raw0[ok], rtol=1e-3, atol=1e-3)


def test_gradient_descriptors_are_unchanged_by_gain_and_offset(photo):
    img = photo["image"]
    changed = (0.7 * img + 20.0).astype(np.float32)
    g0 = photo["grads"]
    g1 = describe_gradients(Level(1.0, 1.0, 0.0, changed), photo["xy"], GradientParams())
    # the same orientations are found (histogram peaks scale with the gain) ...
    assert np.array_equal(g1.index, g0.index)
    np.testing.assert_allclose(g1.angle, g0.angle, atol=1e-3)
    # ... and the normalised histograms are the same (measured max difference 7e-5, angles 2e-5)
    np.testing.assert_allclose(g1.desc, g0.desc, atol=1e-3)


# --------------------------------------------------------------------------------------------
# Nearest neighbours on a rotated, re-lit and noised copy, points detected in both
# --------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def noisy_copy(photo):
    """The copy (137 deg, gain 0.8, offset +15, noise std 3, 8 bits), its points and partners."""
    img = photo["image"]
    a = _rotation_about_centre(img.shape, 137.0)
    rng = np.random.default_rng(7)
    copy = 0.8 * _warp(img, a).astype(np.float64) + 15.0 + rng.normal(0.0, 3.0, img.shape)
    copy = np.clip(np.rint(copy), 0, 255).astype(np.float32)
    xy1 = detect_one(copy, 1.0, HarrisParams()).xy
    d = np.linalg.norm(apply(a, photo["xy"])[:, None] - xy1[None], axis=2)
    nearest = d.argmin(axis=1)
    partner = np.where(d[np.arange(len(d)), nearest] <= 1.5, nearest, -1)
    return dict(image=copy, xy=xy1, partner=partner, level=Level(1.0, 1.0, 0.0, copy))


def test_jets_nearest_neighbour_under_mahalanobis_is_the_true_point(photo, noisy_copy):
    jets1 = whiten(describe_jets(noisy_copy["level"], noisy_copy["xy"], 2.0), photo["whitening"])
    c = match_descriptors(photo["jets"], jets1, MatcherParams(selection="nn"))
    partner = noisy_copy["partner"]
    assert np.array_equal(c.i, np.arange(len(partner)))
    hit = (partner >= 0) & (c.j == partner)
    has = partner >= 0
    # measured: 86.8 % of the points have a partner within 1.5 px (3867 points in the copy);
    # the nearest neighbour is the partner for 50.4 % of all points, 58.1 % of those with one
    assert has.mean() > 0.8
    assert hit.mean() > 0.4
    assert hit[has].mean() > 0.47


def test_gradient_nearest_neighbour_is_the_true_point(photo, noisy_copy):
    g0 = photo["grads"]
    g1 = describe_gradients(noisy_copy["level"], noisy_copy["xy"], GradientParams())
    c = match_descriptors(g0.desc, g1.desc, MatcherParams(selection="nn"))
    # a point's nearest neighbour: the best over its rows (one per dominant orientation)
    n = len(photo["xy"])
    best = np.full(n, np.inf)
    np.minimum.at(best, g0.index[c.i], c.distance)
    win = c.distance <= best[g0.index[c.i]]
    nn = np.full(n, -1)
    nn[g0.index[c.i][win]] = g1.index[c.j][win]
    partner = noisy_copy["partner"]
    has = partner >= 0
    hit = has & (nn == partner)
    # measured: 83.5 % of all points, 96.2 % of those with a partner (jets: 50.4 %, 58.1 %)
    assert hit.mean() > 0.72
    assert hit[has].mean() > 0.88


@pytest.mark.parametrize("shape", [(1, 7), (7, 1), (2, 2), (31, 45)])
def test_gradients_at_points_are_sobels_values_bit_for_bit(shape):
    """The orientation window samples central differences at its points only: the values of the
    full-image Sobel filter (ksize 1, scale 0.5, reflected borders) it replaced, exactly."""
    rng = np.random.default_rng(3)
    img = rng.uniform(0, 255, shape).astype(np.float32)
    py, px = np.mgrid[0:shape[0], 0:shape[1]]
    gx, gy = descriptors._gradients_at(img, px, py)
    assert np.array_equal(gx, cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=1, scale=0.5))
    assert np.array_equal(gy, cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=1, scale=0.5))
