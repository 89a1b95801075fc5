"""Reading images: any common format, grey, colour, RGBA, 16-bit, EXIF-rotated JPEG.

Colour is turned to grey with ITU-R BT.601 luma (0.299 R + 0.587 G + 0.114 B, cv2.COLOR_BGR2GRAY);
16-bit images are scaled to the 8-bit range (so thresholds in grey levels mean the same thing);
the alpha channel of RGBA images is ignored. Errors are ``ImageError`` with a one-line message.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


class ImageError(ValueError):
    """An input image cannot be used; the message says what is wrong."""


def to_grey(image: np.ndarray) -> np.ndarray:
    """Any decoded image array (H, W), (H, W, 3) BGR or (H, W, 4) BGRA -> float32 grey levels."""
    img = np.asarray(image)
    scale = 1.0
    if img.dtype == np.uint16:
        scale = 255.0 / 65535.0
    elif img.dtype.kind == "f":
        scale = 255.0 if img.size and float(np.nanmax(img)) <= 1.0 else 1.0
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[:, :, :3]
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img.astype(np.float32), cv2.COLOR_BGR2GRAY)
    elif img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim != 2:
        raise ImageError(f"unsupported image layout {img.shape}")
    return np.ascontiguousarray(img, dtype=np.float32) * np.float32(scale)


def read_grey(path: str | Path) -> np.ndarray:
    """Read ``path`` as a float32 grey image in 8-bit grey levels (EXIF orientation applied)."""
    p = Path(path)
    if not p.exists():
        raise ImageError(f"{p}: no such file")
    if p.is_dir():
        raise ImageError(f"{p}: is a directory, not an image")
    data = np.fromfile(str(p), dtype=np.uint8)
    if data.size == 0:
        raise ImageError(f"{p}: file is empty")
    img = cv2.imdecode(data, cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR)
    if img is None:
        raise ImageError(f"{p}: not an image OpenCV can decode (or the file is truncated)")
    return to_grey(img)
