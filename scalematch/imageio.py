"""Reading images: any common format, grey, colour, RGBA, 16-bit, EXIF-rotated JPEG.

Colour is turned to grey with ITU-R BT.601 luma (0.299 R + 0.587 G + 0.114 B, cv2.COLOR_BGR2GRAY);
16-bit images are scaled to the 8-bit range (so thresholds in grey levels mean the same thing);
the alpha channel of RGBA images is ignored. Errors are ``ImageError`` with a one-line message
that says what is wrong and what to do.

Safety: the pixel count is read from the file header (PNG, JPEG, BMP, GIF, WebP, TIFF) and checked
against ``max_pixels`` *before* the image is decoded, so a decompression bomb is refused without
allocating it. Other formats are checked right after decoding.

EXIF orientation of JPEG files is read here and applied here (the file is decoded with
``IMREAD_IGNORE_ORIENTATION``), so the result does not depend on whether the installed OpenCV
applies it itself (OpenCV 5 ``imdecode`` does; some older builds did not).
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Optional, Tuple

import cv2
import numpy as np

from .stages.detector import MIN_SIDE_PX

#: Largest image decoded by default, in pixels (100 megapixels: ~400 MB as float32 grey).
DEFAULT_MAX_PIXELS = 100_000_000


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


# --------------------------------------------------------------------------- header parsing

def _jpeg_info(data: bytes) -> Tuple[Optional[Tuple[int, int]], int, int]:
    """((width, height) or None, EXIF orientation 1..8, offset of the first SOS or -1)."""
    size = None
    orientation = 1
    i = 2
    n = len(data)
    while i + 4 <= n:
        if data[i] != 0xFF:
            i += 1
            continue
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
            i += 2
            continue
        if marker == 0xDA:  # start of scan: the header is over
            return size, orientation, i
        (length,) = struct.unpack(">H", data[i + 2:i + 4])
        seg = data[i + 4:i + 2 + length]
        if marker in (0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE,
                      0xCF) and len(seg) >= 5 and size is None:
            h, w = struct.unpack(">HH", seg[1:5])
            size = (w, h)
        elif marker == 0xE1 and seg[:6] == b"Exif\x00\x00":
            orientation = _exif_orientation(seg[6:]) or orientation
        i += 2 + length
    return size, orientation, -1


def _exif_orientation(tiff: bytes) -> Optional[int]:
    """The Orientation tag (0x0112) of IFD0 of a TIFF/EXIF block, or None."""
    try:
        if tiff[:2] == b"II":
            e = "<"
        elif tiff[:2] == b"MM":
            e = ">"
        else:
            return None
        (ifd,) = struct.unpack(e + "I", tiff[4:8])
        (count,) = struct.unpack(e + "H", tiff[ifd:ifd + 2])
        for k in range(count):
            off = ifd + 2 + 12 * k
            tag, typ = struct.unpack(e + "HH", tiff[off:off + 4])
            if tag == 0x0112 and typ == 3:
                (value,) = struct.unpack(e + "H", tiff[off + 8:off + 10])
                return int(value) if 1 <= value <= 8 else None
    except struct.error:
        return None
    return None


def _tiff_size(data: bytes) -> Optional[Tuple[int, int]]:
    e = "<" if data[:2] == b"II" else ">"
    try:
        (ifd,) = struct.unpack(e + "I", data[4:8])
        (count,) = struct.unpack(e + "H", data[ifd:ifd + 2])
        w = h = None
        for k in range(count):
            off = ifd + 2 + 12 * k
            tag, typ = struct.unpack(e + "HH", data[off:off + 4])
            if tag in (256, 257):
                fmt = e + ("H" if typ == 3 else "I")
                (v,) = struct.unpack(fmt, data[off + 8:off + 8 + struct.calcsize(fmt)])
                if tag == 256:
                    w = v
                else:
                    h = v
        return (int(w), int(h)) if w and h else None
    except struct.error:
        return None


def header_size(data: bytes) -> Optional[Tuple[int, int]]:
    """(width, height) from the header of a PNG, JPEG, BMP, GIF, WebP or TIFF file, else None."""
    try:
        if data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR":
            w, h = struct.unpack(">II", data[16:24])
            return int(w), int(h)
        if data[:2] == b"\xff\xd8":
            return _jpeg_info(data)[0]
        if data[:2] == b"BM" and len(data) >= 26:
            w, h = struct.unpack("<ii", data[18:26])
            return abs(int(w)), abs(int(h))
        if data[:6] in (b"GIF87a", b"GIF89a"):
            w, h = struct.unpack("<HH", data[6:10])
            return int(w), int(h)
        if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
            chunk = data[12:16]
            if chunk == b"VP8X":
                w = 1 + int.from_bytes(data[24:27], "little")
                h = 1 + int.from_bytes(data[27:30], "little")
                return w, h
            if chunk == b"VP8L":
                b = int.from_bytes(data[21:25], "little")
                return 1 + (b & 0x3FFF), 1 + ((b >> 14) & 0x3FFF)
            if chunk == b"VP8 ":
                w, h = struct.unpack("<HH", data[26:30])
                return int(w & 0x3FFF), int(h & 0x3FFF)
        if data[:4] in (b"II*\x00", b"MM\x00*"):
            return _tiff_size(data)
    except struct.error:
        return None
    return None


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

    size = header_size(raw)
    if size is not None and max_pixels and size[0] * size[1] > max_pixels:
        raise _too_many(p, size[0], size[1], max_pixels)

    flags = cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR
    orientation = 1
    if raw[:2] == b"\xff\xd8":
        _, orientation, sos = _jpeg_info(raw)
        if sos < 0 or raw.rfind(b"\xff\xd9") < sos:
            raise ImageError(f"{p}: JPEG file is truncated (no end-of-image marker); "
                             "copy or download it again")
        flags |= cv2.IMREAD_IGNORE_ORIENTATION

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
    img = _orient(img, orientation)
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

    See ``read_image`` for the checks and the errors.
    """
    return to_grey(read_image(path, max_pixels=max_pixels, min_side=min_side))
