"""Simulated tilted views: where points go, which views a pass holds, the empty corners."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scalematch.geometry import apply
from scalematch.stages.views import (ViewParams, keep_inside, longitudes, tilt_view, to_high,
                                     view_plan)


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
    assert keep_inside(view, centre, 8.0).all()
    assert not keep_inside(view, corner, 8.0).any()
