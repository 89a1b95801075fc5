"""Reading images: any common format, grey, colour, RGBA, 16-bit, EXIF-rotated JPEG.

Colour is turned to grey with ITU-R BT.601 luma (0.299 R + 0.587 G + 0.114 B, cv2.COLOR_BGR2GRAY);
16-bit images are scaled to the 8-bit range (so thresholds in grey levels mean the same thing);
the alpha channel of RGBA images is ignored. Errors are ``ImageError`` with a one-line message
that says what is wrong and what to do.

Safety: image files are untrusted input. Their header is read by Pillow (``Image.open`` reads
the header only) and the pixel count checked against ``max_pixels`` *before* the image is
decoded, so a decompression bomb is refused without allocating it; formats Pillow does not know
are checked right after OpenCV decodes them. OpenCV decodes the pixels.

The EXIF orientation (JPEG, WebP, PNG ``eXIf`` before the pixels, TIFF) is read from the header by
Pillow and applied here (the file is decoded with ``IMREAD_IGNORE_ORIENTATION``), so the result
does not depend on whether the installed OpenCV applies it itself.
"""

from __future__ import annotations

import io
import math
import warnings
from pathlib import Path
from typing import NamedTuple, Optional, Tuple

import cv2
import numpy as np

from .stages.detector import MIN_SIDE_PX

#: Largest image decoded by default, in pixels (100 megapixels: ~400 MB as float32 grey).
DEFAULT_MAX_PIXELS = 100_000_000


class ImageError(ValueError):
    """An input image cannot be used; the message says what is wrong."""


def to_grey(image: np.ndarray) -> np.ndarray:
    """Any decoded image array (H, W), (H, W, 3) BGR or (H, W, 4) BGRA -> (H, W) float32 grey levels.

    >>> bgr = np.array([[[0, 0, 255], [255, 255, 255]]], np.uint8)  # a red, a white pixel
    >>> to_grey(bgr).astype(float).round(2).tolist()
    [[76.24, 255.0]]
    """
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
    out = np.array(img, dtype=np.float32, order="C")  # always a copy: the caller's stays intact
    if scale != 1.0:  # in place: one pass and one image less (a 24 MP one: 40 ms)
        out *= np.float32(scale)
    return out


def to_bgr8(image: np.ndarray) -> np.ndarray:
    """Any image array (grey float in grey levels, 8/16-bit, BGR, BGRA) -> uint8 (H, W, 3) BGR."""
    img = np.asarray(image)
    if img.dtype == np.uint16:
        img = (img.astype(np.float32) * np.float32(255.0 / 65535.0))
    elif img.dtype.kind == "f" and img.size and float(np.nanmax(img)) <= 1.0:
        img = img * np.float32(255.0)
    img = np.clip(np.nan_to_num(img.astype(np.float32)), 0, 255).astype(np.uint8) \
        if img.dtype != np.uint8 else img
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if img.shape[2] == 1:
        return cv2.cvtColor(img[:, :, 0], cv2.COLOR_GRAY2BGR)
    if img.shape[2] == 4:
        return np.ascontiguousarray(img[:, :, :3])
    return np.ascontiguousarray(img)


def grey_levels(image: np.ndarray, name: str = "image") -> np.ndarray:
    """The check at the edge of ``match``: a 2-D grey array -> float32 8-bit grey levels.

    Scaled as ``to_grey`` scales: floats in [0, 1] (scikit-image's convention) by 255, 16-bit by
    255/65535; other values are taken as grey levels. Raises ``ImageError`` (a ``ValueError``)
    for what would otherwise give "no match" without saying why: a bool array, a NaN or infinite
    value, a constant image; a side under ``MIN_SIDE_PX``.
    """
    img = np.asarray(image)
    if img.dtype == np.bool_:
        raise ImageError(f"the {name} image is a bool array (a mask?); give grey levels, "
                         f"e.g. image.astype(np.uint8) * 255")
    if img.dtype.kind not in "uif":
        raise ImageError(f"the {name} image has dtype {img.dtype}; give grey levels as an "
                         f"integer or float array")
    if img.ndim != 2:
        raise ImageError(f"the {name} image has shape {img.shape}; give a 2-D grey image "
                         f"(scalematch.read_grey reads and converts any image file)")
    if min(img.shape) < MIN_SIDE_PX:
        raise ImageError(f"the {name} image is {img.shape[1]}x{img.shape[0]} px; at least "
                         f"{MIN_SIDE_PX} px on each side is needed")
    lo, hi = float(img.min()), float(img.max())  # nan when any value is nan
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ImageError(f"the {name} image holds NaN or infinite values; replace them "
                         f"(e.g. np.nan_to_num) or crop them out")
    if lo == hi:
        raise ImageError(f"the {name} image is constant (every pixel {lo:g}): there is nothing "
                         f"to match in it")
    return to_grey(img)


# --------------------------------------------------------------------------- the header

class Header(NamedTuple):
    """What Pillow reads from a file's header without decoding its pixels."""

    size: Optional[Tuple[int, int]]  #: (width, height) px as stored, None when not recognised
    orientation: int  #: EXIF orientation 1..8 (1: as stored)
    scan: int  #: JPEG: offset of the first scan (its pixel data), else -1


#: Pillow's default decompression-bomb guard, ``PIL.Image.MAX_IMAGE_PIXELS``: larger PNG files
#: are left to Pillow, whose own limits then apply as for every other format
_PILLOW_MAX_IMAGE_PIXELS = 89_478_485
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_header(data: bytes) -> Optional[Header]:
    """What Pillow would read from a PNG file's header, without importing Pillow (40 ms of a
    whole process, measured with ``python -X importtime``); None when it should judge.

    The size is in the IHDR chunk, which comes first; an orientation can only come from an
    eXIf chunk before the image data (IDAT), so a PNG without one shows as stored.
    """
    if not data.startswith(_PNG_SIGNATURE) or len(data) < 33 or data[12:16] != b"IHDR":
        return None
    width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    if not 0 < width * height <= _PILLOW_MAX_IMAGE_PIXELS:
        return None
    pos = len(_PNG_SIGNATURE)
    while pos + 8 <= len(data):
        kind = data[pos + 4:pos + 8]
        if kind == b"IDAT":
            return Header((width, height), 1, -1)
        if kind == b"eXIf":
            return None
        pos += 12 + int.from_bytes(data[pos:pos + 4], "big")  # length, type, data, CRC
    return None  # no image data: not a PNG to trust


def header(data: bytes) -> Header:
    """The header of an image file, read by Pillow (``Image.open`` is lazy: no pixel is decoded).

    A PNG file without an orientation is read directly (:func:`_png_header`): the same answer.

    A file Pillow does not recognise gives ``size=None``: OpenCV may still decode it, and its
    size is then checked after decoding. Pillow's own decompression-bomb limit
    (``PIL.Image.MAX_IMAGE_PIXELS``, twice it refused outright) raises ``ImageError``.

    >>> import cv2, numpy as np
    >>> png = cv2.imencode(".png", np.zeros((30, 40), np.uint8))[1].tobytes()
    >>> header(png)
    Header(size=(40, 30), orientation=1, scan=-1)
    """
    png = _png_header(data)
    if png is not None:
        return png
    from PIL import Image  # imported when a file is read (40-46 ms), not with scalematch

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Pillow warns about corrupt EXIF and large images
        try:
            with Image.open(io.BytesIO(data)) as im:
                size = (int(im.size[0]), int(im.size[1]))
                orientation = _orientation(im)
                scan = int(im.tile[0][2]) if im.format == "JPEG" and im.tile else -1
        except Image.DecompressionBombError:
            limit = 2 * (Image.MAX_IMAGE_PIXELS or 0)
            raise ImageError(f"image is above Pillow's decompression-bomb limit of "
                             f"{limit / 1e6:.0f} MP (2 x PIL.Image.MAX_IMAGE_PIXELS); shrink it"
                             ) from None
        except Exception:  # noqa: BLE001 (untrusted bytes: any failure means "not recognised")
            return Header(None, 1, -1)
    return Header(size, orientation, scan)


def _orientation(im) -> int:
    """The EXIF Orientation tag (0x0112) of an opened ``PIL.Image``, from the header only
    (``im.getexif()`` may decode a PNG to find it)."""
    from PIL import Image

    try:
        if "exif" in im.info:
            exif = Image.Exif()
            exif.load(im.info["exif"])
            value = exif.get(0x0112, 1)
        else:
            value = getattr(im, "tag_v2", {}).get(0x0112, 1)  # TIFF: a tag of its own IFD
        value = int(value)
    except Exception:  # noqa: BLE001 (a corrupt EXIF block: shown as stored)
        return 1
    return value if 1 <= value <= 8 else 1


def _orient(img: np.ndarray, orientation: int) -> np.ndarray:
    """Apply an EXIF orientation (1..8) so the image shows upright."""
    if orientation == 2:
        img = cv2.flip(img, 1)
    elif orientation == 3:
        img = cv2.rotate(img, cv2.ROTATE_180)
    elif orientation == 4:
        img = cv2.flip(img, 0)
    elif orientation == 5:
        img = cv2.transpose(img)
    elif orientation == 6:
        img = cv2.rotate(img, cv2.ROTATE_90_CLOCKWISE)
    elif orientation == 7:
        img = cv2.rotate(cv2.transpose(img), cv2.ROTATE_180)
    elif orientation == 8:
        img = cv2.rotate(img, cv2.ROTATE_90_COUNTERCLOCKWISE)
    return img


def _too_many(p: Path, w: int, h: int, max_pixels: int) -> ImageError:
    return ImageError(
        f"{p}: image is {w}x{h} = {w * h / 1e6:.1f} MP, above the limit of "
        f"{max_pixels / 1e6:g} MP; shrink it, or raise the limit with --max-pixels "
        f"(max_pixels= in Python) if you have the memory")


# --------------------------------------------------------------------------- reading

def read_image(path: str | Path, max_pixels: int = DEFAULT_MAX_PIXELS,
               min_side: int = MIN_SIDE_PX) -> np.ndarray:
    """Decode ``path`` as stored (grey, BGR or BGRA; 8 or 16 bit), EXIF orientation applied.

    Raises ``ImageError`` (one line, what is wrong and what to do) for a missing file, a directory,
    an empty, truncated or non-image file, an image above ``max_pixels`` pixels (checked from the
    header before decoding where the format allows) or with a side below ``min_side`` px.
    """
    p = Path(path)
    if not p.exists():
        raise ImageError(f"{p}: no such file; check the path")
    if p.is_dir():
        raise ImageError(f"{p}: is a directory, not an image; give an image file")
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise ImageError(f"{p}: cannot read the file ({exc.strerror or exc}); check its permissions")
    if not raw:
        raise ImageError(f"{p}: file is empty; give a PNG, JPEG, TIFF or other image file")

    try:
        head = header(raw)
    except ImageError as exc:
        raise ImageError(f"{p}: {exc}") from None
    size = head.size
    if size is not None and max_pixels and size[0] * size[1] > max_pixels:
        raise _too_many(p, size[0], size[1], max_pixels)
    if head.scan >= 0 and raw.rfind(b"\xff\xd9") < head.scan:
        raise ImageError(f"{p}: JPEG file is truncated (no end-of-image marker); "
                         "copy or download it again")
    # orientation is applied below from the header, the same way for every format and build
    flags = cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR | cv2.IMREAD_IGNORE_ORIENTATION

    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        img = cv2.imdecode(np.frombuffer(raw, dtype=np.uint8), flags)
    except cv2.error:
        img = None
    finally:
        cv2.utils.logging.setLogLevel(level)
    if img is None:
        if size is not None:
            raise ImageError(f"{p}: cannot decode the image (the file looks truncated or "
                             "corrupt); copy or download it again")
        raise ImageError(f"{p}: not an image OpenCV can decode; give a PNG, JPEG, TIFF, BMP or "
                         "WebP file")
    img = _orient(img, head.orientation)
    h, w = img.shape[:2]
    if max_pixels and w * h > max_pixels:
        raise _too_many(p, w, h, max_pixels)
    if min(w, h) < min_side:
        raise ImageError(f"{p}: image is {w}x{h}, too small to match (each side needs at least "
                         f"{min_side} px); give a larger image")
    return img


def read_grey(path: str | Path, max_pixels: int = DEFAULT_MAX_PIXELS,
              min_side: int = MIN_SIDE_PX) -> np.ndarray:
    """Read ``path`` as a float32 grey image in 8-bit grey levels (EXIF orientation applied).

    Parameters
    ----------
    path : str or Path
        Any format OpenCV decodes (PNG, JPEG, TIFF, BMP, WebP, ...); colour becomes BT.601 luma,
        16-bit is scaled to 0..255, alpha is ignored.
    max_pixels : int
        Larger images are refused before decoding (their size is read from the header).
    min_side : int
        Smaller sides are refused, px.

    Returns
    -------
    (H, W) float32 array

    Raises
    ------
    ImageError
        One line saying what is wrong and what to do (see :func:`read_image`).

    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "grey.png")
    >>> cv2.imwrite(path, np.full((40, 60), 200, np.uint8))
    True
    >>> img = read_grey(path)
    >>> img.shape, img.dtype, float(img.max())
    ((40, 60), dtype('float32'), 200.0)
    >>> read_grey(os.path.join(os.path.dirname(path), "missing.png"))
    Traceback (most recent call last):
    ...
    scalematch.imageio.ImageError: .../missing.png: no such file; check the path
    """
    return to_grey(read_image(path, max_pixels=max_pixels, min_side=min_side))
