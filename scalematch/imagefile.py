"""Image files as untrusted input: opened only when a regular file, read within bounds, the
image's size checked from its header before anything is decoded; ``ImageError``, what an input
image that cannot be used raises (a file here, an array in :mod:`scalematch.greylevels`, a
decode in :mod:`scalematch.imageio`), with a one-line message that says what is wrong and what
to do.

Safety: image files are untrusted input, read within bounds (:func:`read_bytes`): only a regular
file is opened (a device such as /dev/zero, a named pipe, a socket is refused before a byte is
read), a file larger than an image within ``max_pixels`` can be (:func:`max_file_bytes`) is
refused from its size, and the header comes from the first ``HEADER_BYTES``. The header
(:mod:`scalematch.headers`) says the image's size *before* the image is decoded, and the size is
checked against ``max_pixels``, the decoder's own limits and ``min_side`` (:func:`check_size`),
so a decompression bomb is refused without allocating it.
"""

from __future__ import annotations

import mmap
import os
import stat
from pathlib import Path
from typing import Any, Tuple

import cv2
import numpy as np

from .headers import BadHeader, Header, header, header_may_follow, tiff_pages

#: Largest image decoded by default, in pixels (100 megapixels: ~400 MB as float32 grey).
DEFAULT_MAX_PIXELS = 100_000_000


class ImageError(ValueError):
    """An input image cannot be used; the message says what is wrong."""


# --------------------------------------------------------------------------- reading

#: Bytes read first, to find the header: Pillow finds a JPEG's size at its SOF marker, after the
#: APPn segments (EXIF, ICC profile, XMP: each at most 64 KiB, several of them in a camera's file);
#: 1 MiB holds them in the files we have seen. When Pillow cannot read the header from this
#: prefix, the rest is read (within ``max_file_bytes``) only if OpenCV knows the file's signature.
HEADER_BYTES = 1 << 20
#: Most bytes one pixel can take in a file OpenCV decodes: four samples of 8 bytes (a 64-bit
#: float RGBA TIFF, uncompressed), the widest layout its readers return.
MAX_BYTES_PER_PIXEL = 32
#: Bytes of a file that are not pixels, at most: metadata (EXIF, ICC profiles, XMP, an embedded
#: preview, as large as a few MB in camera files) and format overhead, with room to spare.
MAX_METADATA_BYTES = 64 << 20


def max_file_bytes(max_pixels: int) -> int:
    """The largest file an image of at most ``max_pixels`` pixels can plausibly be, in bytes:
    every pixel stored uncompressed at the widest layout (``MAX_BYTES_PER_PIXEL``) plus
    ``MAX_METADATA_BYTES``. Larger files are refused before they are read (a multi-page TIFF
    whose pages add up to more too: OpenCV reads only its first page).

    >>> max_file_bytes(100_000_000) / 1e9   # the default --max-pixels
    3.267108864
    """
    return int(max_pixels) * MAX_BYTES_PER_PIXEL + MAX_METADATA_BYTES


def _open_regular(p: Path) -> Tuple[int, int]:
    """(file descriptor, size in bytes) of the regular file ``p``, opened for reading.

    Opened without blocking (a named pipe without a writer would wait for ever), then checked
    with ``fstat`` on the descriptor itself, so what is checked is what is read: a directory,
    a device (/dev/zero, /dev/urandom), a pipe or a socket is refused before any byte is read.
    """
    try:
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    except FileNotFoundError:
        raise ImageError(f"{p}: no such file; check the path") from None
    except IsADirectoryError:
        raise ImageError(f"{p}: is a directory, not an image; give an image file") from None
    except OSError as exc:
        raise ImageError(f"{p}: cannot read the file ({exc.strerror or exc}); check its "
                         "permissions") from None
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            raise ImageError(f"{p}: is a directory, not an image; give an image file")
        if not stat.S_ISREG(st.st_mode):
            kind = ("a named pipe" if stat.S_ISFIFO(st.st_mode) else
                    "a device" if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else
                    "a socket" if stat.S_ISSOCK(st.st_mode) else "not a regular file")
            raise ImageError(f"{p}: is {kind}, not an image file; give an image file")
    except BaseException:
        os.close(fd)
        raise
    return fd, int(st.st_size)


def _read_into(fh: Any, view: memoryview) -> int:
    """Fill ``view`` from the open file ``fh``; the bytes read (fewer only at the end of the file)."""
    got = 0
    while got < len(view):
        k = fh.readinto(view[got:])
        if not k:
            break
        got += k
    return got


def _head(p: Path, data: Any) -> Header:
    try:
        return header(data)
    except BadHeader as exc:
        raise ImageError(f"{p}: {exc}; the file is corrupt, copy or download it again") from None


def read_bytes(path: str | Path, max_pixels: int = DEFAULT_MAX_PIXELS) -> Tuple[bytearray, Header]:
    """The bytes and the header of the image file ``path``, read within bounds.

    In this order, each step refusing (``ImageError``) before the next reads more: a regular
    file (not a directory, device, pipe or socket: :func:`_open_regular`); not empty; not
    larger than :func:`max_file_bytes` of ``max_pixels``; the header, read from the first
    ``HEADER_BYTES``, within ``max_pixels``; a file whose header is not there is read on only
    when OpenCV knows its signature (``cv2.haveImageReader``) and the header may follow
    (:func:`scalematch.headers.header_may_follow`). Memory: the prefix, then the file once.
    """
    p = Path(path)
    fd, size = _open_regular(p)
    with os.fdopen(fd, "rb", buffering=0) as fh:
        if size == 0:
            raise ImageError(f"{p}: file is empty; give a PNG, JPEG, TIFF or other image file")
        limit = max_file_bytes(max_pixels) if max_pixels else 0
        if limit and size > limit:
            raise ImageError(
                f"{p}: file is {size / 1e6:.0f} MB, larger than an image within the limit of "
                f"{max_pixels / 1e6:g} MP can be ({limit / 1e6:.0f} MB: {MAX_BYTES_PER_PIXEL} "
                f"bytes a pixel uncompressed, plus metadata); give an image file, or raise "
                f"--max-pixels (max_pixels= in Python)")
        try:
            prefix = bytearray(min(size, HEADER_BYTES))
            del prefix[_read_into(fh, memoryview(prefix)):]
            head = _head(p, prefix)
            if head.size is not None:
                check_size(p, head.size, max_pixels)
            if len(prefix) == size:
                return prefix, head
            if head.size is None:  # no more bytes read unless they may hold the header
                if not cv2.haveImageReader(str(p)):  # no decoder knows its signature
                    raise not_decodable(p)
                if not header_may_follow(prefix):
                    raise corrupt(p)
            raw = bytearray(size)
            start = len(prefix)
            raw[:start] = prefix
            del prefix
            with memoryview(raw) as view:
                got = start + _read_into(fh, view[start:])
            del raw[got:]  # the file shrank as it was read: what there was
        except OSError as exc:
            raise ImageError(f"{p}: cannot read the file ({exc.strerror or exc}); check its "
                             "permissions") from None
    return raw, (head if head.size is not None else _head(p, raw))


def corrupt(p: Path) -> ImageError:
    return ImageError(f"{p}: cannot decode the image (the file looks truncated or corrupt); "
                      "copy or download it again")


def not_decodable(p: Path) -> ImageError:
    return ImageError(f"{p}: not an image OpenCV can decode; give a PNG, JPEG, TIFF, BMP or "
                      "WebP file")


# --------------------------------------------------------------------------- sizes

def _limit(name: str, default: int) -> int:
    try:
        return int(os.environ.get(name, default))
    except ValueError:
        return default


#: The largest image OpenCV decodes, px, and its longest side (its defaults; the environment
#: variables of the same names change them): a larger one is refused by OpenCV whatever
#: ``max_pixels`` allows, so it is refused from its header with these words.
OPENCV_MAX_PIXELS = _limit("OPENCV_IO_MAX_IMAGE_PIXELS", 1 << 30)
OPENCV_MAX_SIDE = min(_limit("OPENCV_IO_MAX_IMAGE_WIDTH", 1 << 20),
                      _limit("OPENCV_IO_MAX_IMAGE_HEIGHT", 1 << 20))


def check_size(p: Path, size: Tuple[int, int], max_pixels: int, min_side: int = 0) -> None:
    """``ImageError`` unless an image of ``size`` (width, height) px, read from the header of
    the file ``p``, may be decoded: not empty, within ``max_pixels`` (0: no limit) and what
    OpenCV decodes (``OPENCV_MAX_PIXELS``, ``OPENCV_MAX_SIDE``), each side at least
    ``min_side`` px.

    >>> check_size(Path("pano.jpg"), (2_000_000, 30), 0)
    Traceback (most recent call last):
    ...
    scalematch.imagefile.ImageError: pano.jpg: image is 2000000x30 px, longer than the 1048576 px a side OpenCV decodes; shrink it
    """
    w, h = size
    if w <= 0 or h <= 0:
        raise ImageError(f"{p}: the header says the image is {w}x{h} px; the file is corrupt, "
                         "copy or download it again")
    if max_pixels and w * h > max_pixels:
        raise too_many(p, w, h, max_pixels)
    if w * h > OPENCV_MAX_PIXELS:
        raise ImageError(f"{p}: image is {w}x{h} = {_megapixels(w * h)}, above the "
                         f"{_megapixels(OPENCV_MAX_PIXELS)} OpenCV decodes "
                         f"(OPENCV_IO_MAX_IMAGE_PIXELS); shrink it")
    if max(w, h) > OPENCV_MAX_SIDE:
        raise ImageError(f"{p}: image is {w}x{h} px, longer than the {OPENCV_MAX_SIDE} px a side "
                         f"OpenCV decodes; shrink it")
    if min(w, h) < min_side:
        raise too_small(p, w, h, min_side)


def too_small(p: Path, w: int, h: int, min_side: int) -> ImageError:
    return ImageError(f"{p}: image is {w}x{h}, too small to match (each side needs at least "
                      f"{min_side} px); give a larger image")


def too_many(p: Path, w: int, h: int, max_pixels: int) -> ImageError:
    return ImageError(
        f"{p}: image is {w}x{h} = {_megapixels(w * h)}, above the limit of "
        f"{_megapixels(max_pixels)} ({max_pixels} px); shrink it, or raise the limit with --max-pixels "
        f"(max_pixels= in Python) if you have the memory")


def _megapixels(n: float) -> str:
    """``n`` pixels in MP, with as many digits as a small count needs.

    >>> _megapixels(24e6), _megapixels(31635), _megapixels(1000)
    ('24.0 MP', '0.032 MP', '0.001 MP')
    """
    mp = n / 1e6
    return f"{mp:.1f} MP" if mp >= 1 else f"{mp:.2g} MP" if mp >= 0.01 else f"{mp:.1g} MP"


def room_for(p: Path, size: Tuple[int, int]) -> None:
    """``MemoryError`` when there is no room for the image of ``size`` (w, h) as decoded (3
    bytes a pixel): a decode that failed for want of memory (OpenCV returns no image) must not
    be reported as a corrupt file."""
    try:
        np.empty((size[1], size[0], 3), np.uint8).fill(0)  # touched: the pages are taken
    except MemoryError as exc:
        raise MemoryError(f"{p}: no memory to decode the {size[0]}x{size[1]} image") from exc


def pages_of(p: Path) -> int:
    """The pages of the file ``p`` when it is a TIFF (:func:`scalematch.headers.tiff_pages`,
    the file mapped, not read); 1 for another format or a file that cannot be opened again."""
    try:
        fd, size = _open_regular(p)
    except ImageError:
        return 1
    try:
        with mmap.mmap(fd, size, access=mmap.ACCESS_READ) as data:
            return max(tiff_pages(data), 1)
    except (OSError, ValueError):  # emptied since it was read, cannot be mapped
        return 1
    finally:
        os.close(fd)
