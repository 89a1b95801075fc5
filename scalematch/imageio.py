"""Reading images: any common format, grey, colour, RGBA, 16-bit, EXIF-rotated JPEG; a large JPEG
decoded at a reduced size.

:func:`read_grey` gives float32 grey levels (:mod:`scalematch.greylevels`: colour as ITU-R BT.601
luma, 16-bit scaled to the 8-bit range, the alpha channel of RGBA images ignored),
:func:`read_image` the image as stored, :func:`read_reduced` a large JPEG at 1/2, 1/4 or 1/8 of
its size. Errors are ``ImageError`` (:mod:`scalematch.imagefile`) with a one-line message that
says what is wrong and what to do.

Safety: the file is read within bounds and the image's size checked from its header before
anything is decoded (:mod:`scalematch.imagefile`: :func:`read_bytes`, :func:`check_size`), so a
decompression bomb is refused without allocating it; a file whose header cannot be read is not
decoded at all, and a PNG file only once its chunks are known to lie within it. OpenCV decodes
the pixels (faster than Pillow, and holding the image once: docs/design/SPEED.md, "Decoding:
OpenCV, not Pillow").

The decoders' own words: libpng, libjpeg and libtiff write what they find wrong straight to the
process's stderr (file descriptor 2, past ``sys.stderr``), and OpenCV gives no other way to
hear them. Descriptor 2 belongs to the whole process, so by default the library leaves it
alone: the decoders' lines reach stderr as they write them, a file the decoder refuses (OpenCV
gives no image) is an ``ImageError`` saying the file is corrupt, and a file it decodes while
saying something is used as decoded. A process that owns its stderr turns on
:func:`catch_decoder_stderr` (the command line does, while a command runs, and the batch's
worker processes): each decode then catches those lines
(:func:`scalematch.decoderwords.native_stderr`) and says them once, in this module's words,
naming the file: a file the decoder refuses is an ``ImageError`` that quotes the decoder; a
file it decodes while saying something (a damaged JPEG: "Corrupt JPEG data: premature end of
data segment") is used as decoded, and what the decoder said is its warning
(``Decoded.warning``; an ``ImageWarning`` from :func:`read_image` and :func:`read_grey`).

The EXIF orientation (JPEG, WebP, PNG ``eXIf`` before the pixels, TIFF) is read from the header
and applied here (the file is decoded with ``IMREAD_IGNORE_ORIENTATION``), so the result does
not depend on whether the installed OpenCV applies it itself.
"""

from __future__ import annotations

import contextlib
import warnings
from pathlib import Path
from typing import Iterator, List, NamedTuple, Optional, Tuple

import cv2
import numpy as np

from .decoderwords import decoder_words, native_stderr, opencv_log_silenced
from .greylevels import to_grey
from .headers import (IMAGE_SIGNATURES, JPEG_SOI, PNG_SIGNATURE, TIFF_SIGNATURES, Header,
                      png_chunk_problem)
from .imagefile import (DEFAULT_MAX_PIXELS, ImageError, check_size, corrupt, not_decodable,
                        read_bytes, room_for, too_many, too_small)
from .stages.detector import MIN_SIDE_PX


class ImageWarning(UserWarning):
    """An input image was decoded, but its decoder said something was wrong with the file (a
    damaged JPEG, a malformed PNG metadata chunk); the message names the file and quotes the
    decoder."""


# --------------------------------------------------------------------------- the decoders' words

#: Whether each decode catches what the native decoders write on descriptor 2
#: (:func:`catch_decoder_stderr`); off: a library must not take its caller's stderr, whose
#: other threads would have their lines caught and quoted as the decoder's
_catching = False


def catch_decoder_stderr(on: bool = True) -> bool:
    """Whether each decode in this process, from now on, catches what the native decoders write
    on file descriptor 2 and says it in this module's words (``on``); the setting it replaces.

    Off by default. While a decode catches them, descriptor 2 points at a file of no name
    (:func:`scalematch.decoderwords.native_stderr`) and OpenCV's own log is silenced, for the
    whole process: whatever another thread writes to stderr meanwhile is lost (caught, and
    quoted as the decoder's). Turn it on only in a process whose stderr is its own and quiet
    while it decodes: the command line (it decodes before its progress bar starts), a worker
    process.
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


# --------------------------------------------------------------------------- decoding

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
    (:func:`scalematch.decoderwords.native_stderr`)."""
    size = head.size
    if size is not None:
        check_size(p, size, max_pixels, min_side)
    if raw.startswith(PNG_SIGNATURE):  # before OpenCV reads each chunk at its stated length
        problem = png_chunk_problem(raw)
        if problem:
            raise ImageError(f"{p}: {problem}; copy or download it again")
    if size is None:  # nothing is decoded whose size is not known first
        raise corrupt(p) if raw.startswith(IMAGE_SIGNATURES) else not_decodable(p)
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
        raise too_many(p, w, h, max_pixels)
    if min(w, h) * factor < min_side:
        raise too_small(p, w, h, min_side)
    warning = (f"{p}: the {_format_name(raw)} decoder says {words}; the image is used as "
               f"decoded (copy or download the file again if it is damaged)") if words else ""
    return img, warning


def _imdecode(p: Path, raw: bytearray, flags: int, size: Tuple[int, int]
              ) -> Tuple[np.ndarray, str]:
    """OpenCV's decode of ``raw`` (the bytes of ``p``, an image of ``size`` (w, h) px) with
    ``flags``: (the image, the decoder's words quoted by
    :func:`scalematch.decoderwords.decoder_words`, "" when it said nothing or they were not
    caught). They are caught, OpenCV's log silenced meanwhile, only where
    :func:`catch_decoder_stderr` is on. ``ImageError`` (quoting the decoder when its words were
    caught) when it gives no image; ``MemoryError`` when that is for want of memory.
    """
    said: List[str] = []
    if _catching:
        with native_stderr() as said, opencv_log_silenced():
            img = _cv_decode(p, raw, flags)
    else:
        img = _cv_decode(p, raw, flags)
    words = decoder_words(said)
    if img is None:
        room_for(p, size)  # out of memory is not a corrupt file
        if words:
            raise ImageError(f"{p}: cannot decode the image: the {_format_name(raw)} decoder "
                             f"says {words}; the file is corrupt, copy or download it again")
        raise corrupt(p)
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


def read_image(path: str | Path, max_pixels: int = DEFAULT_MAX_PIXELS,
               min_side: int = MIN_SIDE_PX) -> np.ndarray:
    """Decode ``path`` as stored (grey, BGR or BGRA; 8 or 16 bit), EXIF orientation applied.

    Raises ``ImageError`` (one line, what is wrong and what to do) for a missing file, a directory,
    a device or pipe, an empty, truncated or non-image file, a file larger than an image within
    ``max_pixels`` can be, an image above ``max_pixels`` pixels (checked from the header before
    decoding where the format allows) or with a side below ``min_side`` px, or one its decoder
    refuses (quoting the decoder). The file is read within bounds
    (:func:`scalematch.imagefile.read_bytes`).

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
    scalematch.imagefile.ImageError: .../missing.png: no such file; check the path
    """
    return to_grey(_read_warned(path, max_pixels, min_side))
