"""The caption bands of the pictures: lines of white text on a dark band, stacked above or below
a picture (``band``), scaled with its width and wrapped at it (``text_style``).
"""

from __future__ import annotations

from typing import Sequence, Tuple

import cv2
import numpy as np

FONT = cv2.FONT_HERSHEY_SIMPLEX
#: Caption text scale per pixel of the picture's width: text about 2 % of the width tall
#: (a 4608 px overlay: about 80 px, 18 px when viewed whole at 1000 px; a 900 px one: 0.8, about
#: 17 px), so a caption reads the same at any size once the picture fills the screen.
TEXT_SCALE_PER_PX = 1.0 / 1150
#: Smallest caption text scale (below it HERSHEY text is illegible at 1:1).
MIN_TEXT_SCALE = 0.35
#: Grey level of the caption bands above and below a picture.
BAND = 14


def text_style(width: int) -> Tuple[float, int, int]:
    """(font scale, stroke thickness px, margin px) of caption text on a picture ``width`` px
    wide: scaled with the width (``TEXT_SCALE_PER_PX``), never below ``MIN_TEXT_SCALE``.

    >>> text_style(900), text_style(4608)
    ((0.782608695652174, 1, 6), (4.006956521739131, 5, 24))
    """
    scale = max(width * TEXT_SCALE_PER_PX, MIN_TEXT_SCALE)
    return scale, max(1, int(round(scale * 1.2))), max(6, int(round(6 * scale)))


def _layout(lines: Sequence[str], width: int) -> Tuple[list, int, int]:
    """(``lines`` wrapped at ``width`` px, their line step px, the strip's height px)."""
    scale, thick, margin = text_style(width)
    lines = [part for s in lines if s for part in _wrap(s, scale, thick, width - 2 * margin)]
    (_, th), base = cv2.getTextSize("Ag", FONT, scale, thick)
    step = th + base + margin
    return lines, step, (step * len(lines) + margin) if lines else 0


def _wrap(text: str, scale: float, thick: int, width: int) -> list:
    """``text`` broken at spaces into lines no wider than ``width`` px (a long word stays whole)."""
    out, line = [], ""
    for word in text.split(" "):
        trial = f"{line} {word}" if line else word
        if line and cv2.getTextSize(trial, FONT, scale, thick)[0][0] > width:
            out.append(line)
            line = word
        else:
            line = trial
    return out + [line]


def band(lines: Sequence[str], width: int) -> np.ndarray:
    """A dark band ``width`` px wide holding ``lines`` of white caption text, scaled with the
    width (:func:`text_style`) and wrapped at it: stacked above or below a picture."""
    lines, step, strip = _layout(lines, width)
    scale, thick, margin = text_style(width)
    band = np.full((strip + margin, width, 3), BAND, np.uint8)
    (_, th), _ = cv2.getTextSize("Ag", FONT, scale, thick)
    for i, s in enumerate(lines):
        cv2.putText(band, s, (margin, margin // 2 + th + i * step), FONT, scale,
                    (255, 255, 255), thick, cv2.LINE_AA)
    return band
