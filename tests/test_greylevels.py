"""greylevels: every layout drawn as 8-bit BGR, and floats scaled as the matcher reads them."""

from __future__ import annotations

import cv2
import numpy as np

from scalematch.greylevels import to_bgr8


def test_to_bgr8_layouts(bgr):
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    for img in (bgr, grey, grey.astype(np.float32), bgr.astype(np.uint16) * 257,
                np.dstack([bgr, np.zeros(bgr.shape[:2], np.uint8)])):
        out = to_bgr8(img)
        assert out.dtype == np.uint8 and out.shape == bgr.shape


def test_a_float_image_a_little_past_1_is_drawn_as_the_matcher_reads_it():
    """The pictures scale floats as the matcher does (``UNIT_FLOAT_MAX``): a [0, 1] image
    brightened to 1.03 is drawn bright, not black."""
    img = np.linspace(0.0, 1.03, 64, dtype=np.float32).reshape(8, 8)
    drawn = to_bgr8(img)
    assert drawn[..., 0].max() == 255 and abs(float(drawn[0, 1, 0]) - 255 * img[0, 1]) <= 1
