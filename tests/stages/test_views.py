"""Simulated tilted views: where points go, which views a pass holds, the empty corners."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scalematch.geometry import apply
from scalematch.stages.nodata import away_from
from scalematch.stages.views import (View, ViewParams, compressed_x, longitudes,
                                     tilt_view, to_high, view_plan, view_scales)


def test_longitudes_follow_morel_and_yu_sampling():
    # step 72/t degrees over [0, 180): t = 2 -> 36 deg (5 views), t = 4 -> 18 deg (10 views),
    # t = 6 -> 12 deg (15), t = 8 -> 9 deg (20), the last two in one pass
    assert longitudes(2.0, 72.0) == pytest.approx([0, 36, 72, 108, 144])
    assert len(longitudes(4.0, 72.0)) == 10
    assert longitudes(1.0, 72.0) == [0.0]
    plan = view_plan(ViewParams())
    assert [len(p) for p in plan] == [5, 10, 15 + 20]
    assert view_plan(ViewParams(enabled=False)) == []


@pytest.mark.parametrize("tilt,phi", [(2.0, 0.0), (2.0, 36.0), (4.0, 126.0)])
def test_a_bright_dot_lands_where_to_view_maps_it(tilt, phi):
    high = np.zeros((120, 160), np.float32)
    x, y = 97, 41
    high[y - 1:y + 2, x - 1:x + 2] = 255.0
    view = tilt_view(high, tilt, phi)
    px = apply(view.to_view, np.array([[x, y]], float))[0]
    peak = np.unravel_index(np.argmax(view.image), view.image.shape)
    # the blurred dot's maximum lies within a pixel of the mapped centre
    assert abs(peak[1] - px[0]) <= 1.0 and abs(peak[0] - px[1]) <= 1.0
    # the view is compressed by the tilt: its area is about the image's over t
    assert view.image.size == pytest.approx(
        (abs(math.cos(math.radians(phi))) * 160 + abs(math.sin(math.radians(phi))) * 120 + 1)
        * (abs(math.sin(math.radians(phi))) * 160 + abs(math.cos(math.radians(phi))) * 120 + 1)
        / tilt, rel=0.05)
    assert to_high(view, px[None]) == pytest.approx(np.array([[x, y]], float))


def test_points_near_the_empty_corners_are_dropped():
    high = np.full((100, 100), 128.0, np.float32)
    view = tilt_view(high, 2.0, 36.0)  # a turned image: the canvas corners are empty
    centre = apply(view.to_view, np.array([[50.0, 50.0]]))
    corner = np.array([[0.0, 0.0]])  # canvas corner: outside the turned image
    # the detector drops points by the view's distance to its empty canvas (detect_on_level)
    assert away_from(view.inside_distance, centre, 8.0).all()
    assert not away_from(view.inside_distance, corner, 8.0).any()


@pytest.mark.parametrize("tilt,phi", [(2.0, 0.0), (4.0, 126.0)])
def test_a_view_simulated_on_the_image_decimated_maps_points_as_its_scale_says(tilt, phi):
    """An image whose shorter side is twice ``max_short_side_px`` has its views made from it
    shrunk by 2: a dot lands where ``to_view`` maps it, within a view pixel, and the view's
    pixels are 2 image pixels along its uncompressed direction (``View.scale``)."""
    high = np.zeros((240, 320), np.float32)
    x, y = 197, 81
    high[y - 2:y + 3, x - 2:x + 3] = 255.0
    view = tilt_view(high, tilt, phi, ViewParams(max_short_side_px=120.0))
    full = tilt_view(high, tilt, phi, ViewParams(max_short_side_px=0.0))
    assert view.scale == 2.0 and full.scale == 1.0 and view.source_shape == (240, 320)
    px = apply(view.to_view, np.array([[x, y]], float))[0]
    peak = np.unravel_index(np.argmax(view.image), view.image.shape)
    assert abs(peak[1] - px[0]) <= 1.0 and abs(peak[0] - px[1]) <= 1.0
    assert view.image.size == pytest.approx(full.image.size / 4, rel=0.1)


def test_the_anti_aliasing_in_halvings_blurs_as_one_gaussian_would():
    """A step edge compressed by t = 8 in halvings spreads as Morel & Yu's single blur of
    0.8 sqrt(t^2 - 1) px would, then shrunk: the widths of the two ramps (10 % to 90 %, in
    compressed px) agree within one compressed pixel."""
    import cv2

    img = np.zeros((8, 512), np.float32)
    img[:, 256:] = 255.0
    t, c = 8.0, 0.8
    halved = compressed_x(img, t, c)[4]
    one = cv2.resize(cv2.GaussianBlur(img, (0, 0), sigmaX=c * math.sqrt(t * t - 1), sigmaY=0.01),
                     (64, 8), interpolation=cv2.INTER_LINEAR)[4]

    def ramp(row):
        return np.count_nonzero((row > 25.5) & (row < 229.5))

    assert halved.shape == one.shape == (64,)
    assert abs(ramp(halved) - ramp(one)) <= 1


def test_a_view_serves_the_scales_its_pixels_can_hold():
    v = View(2.0, 0.0, np.zeros((4, 4), np.float32), np.eye(2, 3), scale=2.0)
    assert view_scales(v, (4.0, 1.0, 2.0, 3.17)) == [1.0, 1.585, 2.0]
    assert view_scales(View(1.0, 0.0, np.zeros((4, 4), np.float32), np.eye(2, 3)),
                       (2.0, 1.0)) == [1.0, 2.0]
