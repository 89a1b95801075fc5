"""Reading images: any common format, grey, colour, RGBA, 16-bit, EXIF-rotated JPEG.

Colour is turned to grey with ITU-R BT.601 luma (0.299 R + 0.587 G + 0.114 B, cv2.COLOR_BGR2GRAY);
16-bit images are scaled to the 8-bit range (so thresholds in grey levels mean the same thing);
the alpha channel of RGBA images is ignored. Errors are ``ImageError`` with a one-line message
that says what is wrong and what to do.

Safety: image files are untrusted input, read within bounds (:func:`read_bytes`): only a regular
file is opened (a device such as /dev/zero, a named pipe, a socket is refused before a byte is
read), a file larger than an image within ``max_pixels`` can be (:func:`max_file_bytes`) is
refused from its size, and the header comes from the first ``HEADER_BYTES``. The header
(:mod:`scalematch.headers`) says the image's size *before* the image is decoded, and the size is
checked against ``max_pixels``, the decoder's own limits and ``min_side`` (:func:`check_size`),
so a decompression bomb is refused without allocating it; a file whose header cannot be read
is not decoded at all, and a PNG file only once its chunks are known to lie within it. OpenCV
decodes the pixels (faster than Pillow, and holding the image once: docs/design/SPEED.md,
"Decoding: OpenCV, not Pillow").

The decoders' own words: libpng, libjpeg and libtiff write what they find wrong straight to the
process's stderr (file descriptor 2, past ``sys.stderr``), and OpenCV gives no other way to
hear them. Descriptor 2 belongs to the whole process, so by default the library leaves it
alone: the decoders' lines reach stderr as they write them, a file the decoder refuses (OpenCV
gives no image) is an ``ImageError`` saying the file is corrupt, and a file it decodes while
saying something is used as decoded. A process that owns its stderr turns on
:func:`catch_decoder_stderr` (the command line does, while a command runs, and the batch's
worker processes): each decode then catches those lines (:func:`native_stderr`) and says them
once, in this module's words, naming the file: a file the decoder refuses is an ``ImageError``
that quotes the decoder; a file it decodes while saying something (a damaged JPEG: "Corrupt
JPEG data: premature end of data segment") is used as decoded, and what the decoder said is
its warning (``Decoded.warning``; an ``ImageWarning`` from :func:`read_image` and
:func:`read_grey`).

The EXIF orientation (JPEG, WebP, PNG ``eXIf`` before the pixels, TIFF) is read from the header
and applied here (the file is decoded with ``IMREAD_IGNORE_ORIENTATION``), so the result does
not depend on whether the installed OpenCV applies it itself.
"""

from __future__ import annotations

import contextlib
import math
import mmap
import os
import stat
import sys
import tempfile
import threading
import warnings
from pathlib import Path
from typing import Any, Iterator, List, NamedTuple, Optional, Tuple

import cv2
import numpy as np

from .headers import (IMAGE_SIGNATURES, JPEG_SOI, MAX_TIFF_PAGES, PNG_SIGNATURE, TIFF_SIGNATURES,
                      BadHeader, Header, header, header_may_follow, png_chunk_problem, tiff_pages)
from .stages.detector import MIN_SIDE_PX

#: Largest image decoded by default, in pixels (100 megapixels: ~400 MB as float32 grey).
DEFAULT_MAX_PIXELS = 100_000_000


#: A float image whose largest value is at most this is taken as scaled to [0, 1] (scikit-image's
#: convention) and multiplied by 255: a [0, 1] image brightened, or resampled with a cubic
#: kernel, overshoots 1 a little (a copy brightened 8 % reached 1.03 and, read as 0-255 grey
#: levels, matched nothing), while grey levels 0-255 whose brightest pixel is under 2 hold
#: less than two levels of contrast, nothing to match either way
UNIT_FLOAT_MAX = 2.0


class ImageError(ValueError):
    """An input image cannot be used; the message says what is wrong."""


class ImageWarning(UserWarning):
    """An input image was decoded, but its decoder said something was wrong with the file (a
    damaged JPEG, a malformed PNG metadata chunk); the message names the file and quotes the
    decoder."""


def _level_scale(img: np.ndarray) -> float:
    """The factor that brings ``img``'s values to 8-bit grey levels: 255/65535 for 16-bit, 255
    for floats at most ``UNIT_FLOAT_MAX`` (an image in [0, 1]), else 1."""
    if img.dtype == np.uint16:
        return 255.0 / 65535.0
    if img.dtype.kind == "f" and img.size and float(np.nanmax(img)) <= UNIT_FLOAT_MAX:
        return 255.0
    return 1.0


def to_grey(image: np.ndarray) -> np.ndarray:
    """Any decoded image array (H, W), (H, W, 3) BGR or (H, W, 4) BGRA -> (H, W) float32 grey levels.

    >>> bgr = np.array([[[0, 0, 255], [255, 255, 255]]], np.uint8)  # a red, a white pixel
    >>> to_grey(bgr).astype(float).round(2).tolist()
    [[76.24, 255.0]]
    """
    img = np.asarray(image)
    scale = _level_scale(img)
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
    """Any image array (grey float in grey levels or in [0, 1], as :func:`to_grey` reads it;
    8/16-bit, BGR, BGRA) -> uint8 (H, W, 3) BGR."""
    img = np.asarray(image)
    scale = _level_scale(img)
    if scale != 1.0:
        img = img.astype(np.float32) * np.float32(scale)
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
    """The check at the edge of ``match``: a 2-D grey array (or one channel, (H, W, 1)) ->
    float32 8-bit grey levels.

    Scaled as ``to_grey`` scales: floats at most ``UNIT_FLOAT_MAX`` (images in [0, 1],
    scikit-image's convention, a little past 1 when brightened or resampled) by 255, 16-bit by
    255/65535; other values are taken as grey levels. Raises ``ImageError`` (a ``ValueError``)
    for what would otherwise give "no match" without saying why: a bool array, a NaN or infinite
    value, a constant image; a side under ``MIN_SIDE_PX``.
    """
    img = np.asarray(image)
    if img.dtype == np.bool_:
        raise ImageError(f"the {name} image is a bool array (a mask?); give grey levels, "
                         f"e.g. image.astype(np.uint8) * 255")
    if isinstance(image, (str, os.PathLike)) or img.dtype.kind in "USO" and img.ndim == 0:
        raise ImageError(f"the {name} image is a path ({str(image)!r}), not an array; read it "
                         f"first: scalematch.read_grey({str(image)!r})")
    if img.dtype.kind not in "uif":
        raise ImageError(f"the {name} image has dtype {img.dtype}; give grey levels as an "
                         f"integer or float array (scalematch.read_grey reads an image file)")
    if img.ndim == 3 and img.shape[2] == 1:  # one channel, as some readers give grey images
        img = img[:, :, 0]
    if img.ndim != 2:
        raise ImageError(f"the {name} image has shape {img.shape}; give a 2-D grey image "
                         f"(scalematch.read_grey reads and converts any image file)")
    if min(img.shape) < MIN_SIDE_PX:
        raise ImageError(f"the {name} image is {img.shape[1]}x{img.shape[0]} px; at least "
                         f"{MIN_SIDE_PX} px on each side is needed")
    problem = _levels_problem(img)
    if problem:
        raise ImageError(f"the {name} image {problem}")
    return to_grey(img)


def _levels_problem(img: np.ndarray) -> str:
    """What leaves nothing to match in the grey levels of ``img``, or "": NaN or infinite
    values, or a constant image."""
    lo, hi = float(img.min()), float(img.max())  # nan when any value is nan
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "holds NaN or infinite values; replace them (e.g. np.nan_to_num) or crop them out"
    if lo == hi:
        return f"is constant (every pixel {lo:g}): there is nothing to match in it"
    return ""


def grey_of_file(image: np.ndarray, path: str | Path) -> np.ndarray:
    """The grey levels (:func:`to_grey`) of ``image``, decoded from the file ``path``;
    ``ImageError`` naming the file when they leave nothing to match (a constant image, NaN
    or infinite values), as :func:`grey_levels` would without its name. Of a TIFF of several
    pages only the first is decoded, and a blank first page is common (a cover, a mask): the
    message then says so.

    >>> grey_of_file(np.full((30, 40), 7, np.uint8), "flat.png")
    Traceback (most recent call last):
    ...
    scalematch.imageio.ImageError: flat.png: image is constant (every pixel 7): there is nothing to match in it
    """
    grey = to_grey(image)
    problem = _levels_problem(grey)
    if problem:
        pages = _pages(Path(path))
        if pages > 1:  # the page read may not be the one the user looks at
            more = " or more" if pages >= MAX_TIFF_PAGES else ""
            raise ImageError(f"{path}: image {problem}; the file is a TIFF of {pages}{more} "
                             f"pages and only the first is read: save the page wanted as an "
                             f"image file of its own")
        raise ImageError(f"{path}: image {problem}")
    return grey


def _pages(p: Path) -> int:
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


def _megapixels(n: float) -> str:
    """``n`` pixels in MP, with as many digits as a small count needs.

    >>> _megapixels(24e6), _megapixels(31635), _megapixels(1000)
    ('24.0 MP', '0.032 MP', '0.001 MP')
    """
    mp = n / 1e6
    return f"{mp:.1f} MP" if mp >= 1 else f"{mp:.2g} MP" if mp >= 0.01 else f"{mp:.1g} MP"


def _too_many(p: Path, w: int, h: int, max_pixels: int) -> ImageError:
    return ImageError(
        f"{p}: image is {w}x{h} = {_megapixels(w * h)}, above the limit of "
        f"{_megapixels(max_pixels)} ({max_pixels} px); shrink it, or raise the limit with --max-pixels "
        f"(max_pixels= in Python) if you have the memory")


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
                    raise _not_decodable(p)
                if not header_may_follow(prefix):
                    raise _corrupt(p)
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


def _corrupt(p: Path) -> ImageError:
    return ImageError(f"{p}: cannot decode the image (the file looks truncated or corrupt); "
                      "copy or download it again")


def _not_decodable(p: Path) -> ImageError:
    return ImageError(f"{p}: not an image OpenCV can decode; give a PNG, JPEG, TIFF, BMP or "
                      "WebP file")


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
    scalematch.imageio.ImageError: pano.jpg: image is 2000000x30 px, longer than the 1048576 px a side OpenCV decodes; shrink it
    """
    w, h = size
    if w <= 0 or h <= 0:
        raise ImageError(f"{p}: the header says the image is {w}x{h} px; the file is corrupt, "
                         "copy or download it again")
    if max_pixels and w * h > max_pixels:
        raise _too_many(p, w, h, max_pixels)
    if w * h > OPENCV_MAX_PIXELS:
        raise ImageError(f"{p}: image is {w}x{h} = {_megapixels(w * h)}, above the "
                         f"{_megapixels(OPENCV_MAX_PIXELS)} OpenCV decodes "
                         f"(OPENCV_IO_MAX_IMAGE_PIXELS); shrink it")
    if max(w, h) > OPENCV_MAX_SIDE:
        raise ImageError(f"{p}: image is {w}x{h} px, longer than the {OPENCV_MAX_SIDE} px a side "
                         f"OpenCV decodes; shrink it")
    if min(w, h) < min_side:
        raise _too_small(p, w, h, min_side)


def _too_small(p: Path, w: int, h: int, min_side: int) -> ImageError:
    return ImageError(f"{p}: image is {w}x{h}, too small to match (each side needs at least "
                      f"{min_side} px); give a larger image")


def _room_for(p: Path, size: Tuple[int, int]) -> None:
    """``MemoryError`` when there is no room for the image of ``size`` (w, h) as decoded (3
    bytes a pixel): a decode that failed for want of memory (OpenCV returns no image) must not
    be reported as a corrupt file."""
    try:
        np.empty((size[1], size[0], 3), np.uint8).fill(0)  # touched: the pages are taken
    except MemoryError as exc:
        raise MemoryError(f"{p}: no memory to decode the {size[0]}x{size[1]} image") from exc


# --------------------------------------------------------------------------- the decoders' words

#: Most bytes of what the native decoders write on stderr during one decode that are read back:
#: libjpeg says only its first warning, libpng and libtiff one line before they give up.
NATIVE_TEXT_BYTES = 4096
#: Most lines of it quoted, and most characters of each.
NATIVE_LINES, NATIVE_LINE_CHARS = 3, 200
#: File descriptor 2 belongs to the whole process: one decode at a time has it redirected (a
#: block inside another, in the same thread, redirects it again and gives it back to the outer).
_STDERR_LOCK = threading.RLock()
#: Whether each decode catches what the native decoders write on descriptor 2
#: (:func:`catch_decoder_stderr`); off: a library must not take its caller's stderr, whose
#: other threads would have their lines caught and quoted as the decoder's
_catching = False


def catch_decoder_stderr(on: bool = True) -> bool:
    """Whether each decode in this process, from now on, catches what the native decoders write
    on file descriptor 2 and says it in this module's words (``on``); the setting it replaces.

    Off by default. While a decode catches them, descriptor 2 points at a temporary file
    (:func:`native_stderr`) and OpenCV's own log is silenced, for the whole process: whatever
    another thread writes to stderr meanwhile is lost (caught, and quoted as the decoder's).
    Turn it on only in a process whose stderr is its own and quiet while it decodes: the
    command line (it decodes before its progress bar starts), a worker process.
    """
    global _catching
    before, _catching = _catching, bool(on)
    return before


@contextlib.contextmanager
def decoder_stderr_caught() -> Iterator[None]:
    """:func:`catch_decoder_stderr` on while the block runs, as it was after (a command run
    inside a caller's process leaves the setting as it found it)."""
    before = catch_decoder_stderr(True)
    try:
        yield
    finally:
        catch_decoder_stderr(before)


@contextlib.contextmanager
def native_stderr() -> Iterator[List[str]]:
    """What native code writes on the process's stderr while the block runs (file descriptor 2,
    which the C libraries write to directly, past ``sys.stderr``): its lines, in the list
    yielded, filled once the block ends; none of it reaches the real stderr.

    Descriptor 2 is pointed at a temporary file meanwhile and set back after, whatever the
    block raises. It belongs to the whole process, so one thread at a time redirects it (the
    others wait): whatever another thread writes to it meanwhile is caught too. When it cannot
    be redirected (closed, or no temporary file can be made), the block runs as it is and the
    list stays empty.

    >>> with native_stderr() as said:
    ...     _ = os.write(2, b"libpng error: IDAT: CRC error\\n")
    >>> said
    ['libpng error: IDAT: CRC error']
    """
    said: List[str] = []
    with _STDERR_LOCK:
        redirected = _stderr_to_file()
        if redirected is None:
            yield said
            return
        sink, saved = redirected
        try:
            yield said
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            with sink:
                sink.seek(0)
                text = sink.read(NATIVE_TEXT_BYTES).decode("utf-8", "replace")
            said.extend(line.strip() for line in text.splitlines() if line.strip())


def _stderr_to_file() -> Optional[Tuple[Any, int]]:
    """Point file descriptor 2 at a new temporary file: (the file, a duplicate of what
    descriptor 2 was); None, nothing changed, when there is no stderr or no temporary file."""
    try:
        sys.stderr.flush()  # Python's own text, written before, stays on the real stderr
    except (AttributeError, OSError, ValueError):
        pass
    try:
        sink = tempfile.TemporaryFile()
    except OSError:
        return None
    try:
        saved = os.dup(2)
    except OSError:  # no stderr at all: nothing to keep quiet
        sink.close()
        return None
    try:
        os.dup2(sink.fileno(), 2)
    except OSError:
        os.close(saved)
        sink.close()
        return None
    return sink, saved


#: The prefixes libpng puts before its words (its default error and warning handlers).
_NATIVE_PREFIXES = ("libpng error: ", "libpng warning: ")


def decoder_words(lines: List[str]) -> str:
    """What a decoder said (:func:`native_stderr`'s lines) as one quotation: the first
    ``NATIVE_LINES`` distinct lines, each at most ``NATIVE_LINE_CHARS``, without libpng's
    prefixes; "" when it said nothing.

    >>> decoder_words(["libpng error: IDAT: CRC error"])
    '"IDAT: CRC error"'
    >>> decoder_words(["Corrupt JPEG data: premature end of data segment"] * 2 + ["Bogus"])
    '"Corrupt JPEG data: premature end of data segment; Bogus"'
    """
    out: List[str] = []
    for line in lines:
        for prefix in _NATIVE_PREFIXES:
            if line.startswith(prefix):
                line = line[len(prefix):]
        line = line[:NATIVE_LINE_CHARS]
        if line and line not in out:
            out.append(line)
    return f'"{"; ".join(out[:NATIVE_LINES])}"' if out else ""


def _format_name(raw: bytes) -> str:
    """The format of the file whose bytes are ``raw``, as its decoder is named in messages."""
    if raw.startswith(PNG_SIGNATURE):
        return "PNG"
    if raw.startswith(JPEG_SOI):
        return "JPEG"
    if raw.startswith(TIFF_SIGNATURES):
        return "TIFF"
    if raw.startswith(b"RIFF") and raw[8:12] == b"WEBP":
        return "WebP"
    return "image"


#: Reduction factors of a JPEG decoded at a reduced size, largest first: libjpeg's DCT scaling
#: (OpenCV's ``IMREAD_REDUCED_*`` modes, flag bits 64, 32, 16) decodes 1/8, 1/4 or 1/2 of each
#: side directly, the pixel ``x`` of the reduced image standing for file pixels
#: ``[f x, f x + f)``: centred at ``f x + (f - 1) / 2``, the map of a shrink by ``f``
#: (:mod:`scalematch.working`). Measured on a 16 MP photo of ../shared (snowpeak_IMG_2282):
#: equal to the full decode shrunk by ``cv2.INTER_AREA`` within 0.35 grey levels rms (the
#: decoder's own rounding to 8 bits is 0.29), shifted by less than 0.001 px (phase
#: correlation), at 1/2, 1/4 and 1/8 alike (docs/design/SPEED.md, "Working size").
REDUCED_FLAGS = {8: cv2.IMREAD_REDUCED_GRAYSCALE_8, 4: cv2.IMREAD_REDUCED_GRAYSCALE_4,
                 2: cv2.IMREAD_REDUCED_GRAYSCALE_2}
#: A reduced decode may fall this much short of the side asked for: the photos of 12 MP cameras
#: and phones, 4000 and 4032 px, then decode at half size (2000 and 2016 px against a working
#: size of 2048) -- the commonest size of photo, 2.3 % less resolution for half the decoding
#: time and a quarter of the memory (docs/design/SPEED.md, "Working size": the answers
#: measured)
REDUCED_SLACK = 0.03


class Decoded(NamedTuple):
    """An image file as decoded, maybe at a reduced size (:func:`read_reduced`)."""

    image: np.ndarray  #: as :func:`read_image` returns it, maybe ``factor`` times smaller
    factor: int  #: file px per image px (1: full size); x_file = factor x + (factor - 1) / 2
    size: Tuple[int, int]  #: (width, height) of the image in the file, orientation applied
    #: what the decoder said was wrong with the file it decoded anyway (a damaged JPEG), the
    #: file named ("": nothing)
    warning: str = ""

    @property
    def shape(self) -> Tuple[int, int]:
        """(height, width) of the image in the file: as ``MatchResult.to_dict`` takes it."""
        return self.size[1], self.size[0]


def reduction(head: Header, at_least: Optional[int], min_side: int = MIN_SIDE_PX) -> int:
    """The factor (1, 2, 4 or 8) at which a file of header ``head`` is decoded so that its longer
    side stays at least ``at_least`` px (less ``REDUCED_SLACK``) and its shorter side at least
    ``min_side``: the largest in ``REDUCED_FLAGS`` that does, for a JPEG (``head.scan`` known)
    only; 1 for other formats, or when ``at_least`` is None.

    >>> jpeg = Header((4608, 3456), 1, 600)
    >>> reduction(jpeg, 2048), reduction(jpeg, 1024), reduction(jpeg, 4000), reduction(jpeg, None)
    (2, 4, 1, 1)
    >>> reduction(Header((4000, 3000), 1, 600), 2048), reduction(Header((3840, 2160), 1, 600), 2048)
    (2, 1)
    >>> reduction(Header((4608, 3456), 1, -1), 1024)   # not a JPEG
    1
    >>> reduction(Header((44160, 160), 1, 600), 2048)   # 20 px high at 1/8: too thin
    4
    """
    if at_least is None or head.size is None or head.scan < 0:
        return 1
    side, short = max(head.size), min(head.size)
    return next((f for f in REDUCED_FLAGS if side / f >= at_least * (1.0 - REDUCED_SLACK)
                 and short / f >= min_side), 1)


def _decode(p: Path, raw: bytearray, head: Header, max_pixels: int, min_side: int,
            factor: int = 1) -> Tuple[np.ndarray, str]:
    """The pixels of ``raw`` (the bytes of ``p``, header ``head``) decoded, EXIF orientation
    applied, at ``1 / factor`` of each side for a JPEG (:func:`reduction`); and the warning of
    a file the decoder decoded while saying something was wrong with it ("" when it said
    nothing). A file it refuses is an ``ImageError`` quoting what it said
    (:func:`native_stderr`)."""
    size = head.size
    if size is not None:
        check_size(p, size, max_pixels, min_side)
    if raw.startswith(PNG_SIGNATURE):  # before OpenCV reads each chunk at its stated length
        problem = png_chunk_problem(raw)
        if problem:
            raise ImageError(f"{p}: {problem}; copy or download it again")
    if size is None:  # nothing is decoded whose size is not known first
        raise _corrupt(p) if raw.startswith(IMAGE_SIGNATURES) else _not_decodable(p)
    if head.scan >= 0 and raw.rfind(b"\xff\xd9") < head.scan:
        raise ImageError(f"{p}: JPEG file is truncated (no end-of-image marker); "
                         "copy or download it again")
    # orientation is applied below from the header, the same way for every format and build
    flags = cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR | cv2.IMREAD_IGNORE_ORIENTATION
    if factor > 1:
        flags |= REDUCED_FLAGS[factor]

    img, words = _imdecode(p, raw, flags, size)
    img = _orient(img, head.orientation)
    h, w = img.shape[:2]
    if max_pixels and w * h * factor * factor > max_pixels:
        raise _too_many(p, w, h, max_pixels)
    if min(w, h) * factor < min_side:
        raise _too_small(p, w, h, min_side)
    warning = (f"{p}: the {_format_name(raw)} decoder says {words}; the image is used as "
               f"decoded (copy or download the file again if it is damaged)") if words else ""
    return img, warning


def _imdecode(p: Path, raw: bytearray, flags: int, size: Tuple[int, int]
              ) -> Tuple[np.ndarray, str]:
    """OpenCV's decode of ``raw`` (the bytes of ``p``, an image of ``size`` (w, h) px) with
    ``flags``: (the image, the decoder's words quoted by :func:`decoder_words`, "" when it said
    nothing or they were not caught). They are caught, OpenCV's log silenced meanwhile, only
    where :func:`catch_decoder_stderr` is on. ``ImageError`` (quoting the decoder when its
    words were caught) when it gives no image; ``MemoryError`` when that is for want of memory.
    """
    said: List[str] = []
    if _catching:
        with native_stderr() as said, _opencv_log_silenced():
            img = _cv_decode(p, raw, flags)
    else:
        img = _cv_decode(p, raw, flags)
    words = decoder_words(said)
    if img is None:
        _room_for(p, size)  # out of memory is not a corrupt file
        if words:
            raise ImageError(f"{p}: cannot decode the image: the {_format_name(raw)} decoder "
                             f"says {words}; the file is corrupt, copy or download it again")
        raise _corrupt(p)
    return img, words


def _cv_decode(p: Path, raw: bytearray, flags: int) -> Optional[np.ndarray]:
    """``cv2.imdecode`` of ``raw`` (the bytes of ``p``) with ``flags``: None when OpenCV gives
    no image or raises; ``MemoryError`` when it raises for want of memory."""
    try:
        return cv2.imdecode(np.frombuffer(raw, dtype=np.uint8), flags)
    except cv2.error as exc:
        if "Insufficient memory" in str(exc):
            raise MemoryError(f"{p}: no memory to decode the image") from exc
        return None


@contextlib.contextmanager
def _opencv_log_silenced() -> Iterator[None]:
    """OpenCV's log silenced while the block runs (its lines would be caught with the
    decoder's, as if the decoder said them), its level as it was after. The level is the
    process's: only under :func:`native_stderr`'s lock, so two threads do not each restore
    the other's silence."""
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        cv2.utils.logging.setLogLevel(level)


def read_image(path: str | Path, max_pixels: int = DEFAULT_MAX_PIXELS,
               min_side: int = MIN_SIDE_PX) -> np.ndarray:
    """Decode ``path`` as stored (grey, BGR or BGRA; 8 or 16 bit), EXIF orientation applied.

    Raises ``ImageError`` (one line, what is wrong and what to do) for a missing file, a directory,
    a device or pipe, an empty, truncated or non-image file, a file larger than an image within
    ``max_pixels`` can be, an image above ``max_pixels`` pixels (checked from the header before
    decoding where the format allows) or with a side below ``min_side`` px, or one its decoder
    refuses (quoting the decoder). The file is read within bounds (:func:`read_bytes`).

    Warns (``ImageWarning``: the file named, the decoder quoted) of a file the decoder decodes
    while saying something is wrong with it (a damaged JPEG); the image is returned as decoded.
    """
    return _read_warned(path, max_pixels, min_side)


def _read_warned(path: str | Path, max_pixels: int, min_side: int) -> np.ndarray:
    """:func:`read_image`'s work; its ``ImageWarning`` points at the line that called the
    public function (``read_image``, ``read_grey``)."""
    p = Path(path)
    raw, head = read_bytes(p, max_pixels)
    img, warning = _decode(p, raw, head, max_pixels, min_side)
    if warning:
        warnings.warn(warning, ImageWarning, stacklevel=3)
    return img


def read_reduced(path: str | Path, at_least: Optional[int],
                 max_pixels: int = DEFAULT_MAX_PIXELS, min_side: int = MIN_SIDE_PX) -> Decoded:
    """Decode ``path`` as :func:`read_image` does, but a JPEG whose longer side is at least
    twice ``at_least`` px at 1/2, 1/4 or 1/8 of its size (:func:`reduction`): the longer side
    stays at least ``at_least`` (the working size: ``scalematch.working.decode_sides``), or
    ``REDUCED_SLACK`` short of it.

    A 16 MP camera JPEG against a 2048 px working size: decoded at half size, 0.05 s instead
    of 0.1 s, and 12 MB instead of 48 MB of pixels (its grey copy: 16 MB instead of 64 MB).
    ``Decoded.factor`` says how much smaller the image is than the file's; ``match`` takes it
    (``decoded_factors``) and answers in the file's pixels. What the decoder said was wrong
    with a file it decoded is ``Decoded.warning`` (no ``ImageWarning``: the caller says it).

    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "big.jpg")
    >>> cv2.imwrite(path, np.tile(np.arange(256, dtype=np.uint8), (600, 5)))
    True
    >>> d = read_reduced(path, at_least=300)
    >>> d.image.shape, d.factor, d.size
    ((150, 320), 4, (1280, 600))
    """
    p = Path(path)
    raw, head = read_bytes(p, max_pixels)
    factor = reduction(head, at_least, min_side)
    img, warning = _decode(p, raw, head, max_pixels, min_side, factor)
    h, w = img.shape[:2]
    if factor == 1:
        return Decoded(img, 1, (w, h), warning)
    fw, fh = head.size  # as stored; orientations 5 to 8 turn it by a quarter
    return Decoded(img, factor, (fw, fh) if head.orientation <= 4 else (fh, fw), warning)


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

    Warns
    -----
    ImageWarning
        A file its decoder decoded while saying something is wrong with it (see
        :func:`read_image`).

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
    return to_grey(_read_warned(path, max_pixels, min_side))
