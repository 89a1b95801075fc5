"""What an image file's header says, read before a pixel is decoded: its size and orientation,
and whether the decoder can be trusted with it.

Image files are untrusted input. :mod:`scalematch.imagefile` reads a file's header here first
and checks the size against its limits; only then does :mod:`scalematch.imageio` let OpenCV
decode the pixels. Pillow reads most headers (``Image.open`` is lazy: no pixel is decoded); PNG
files are read here directly, every chunk of them, because OpenCV's PNG reader allocates each
chunk at the length its length field states before it finds the file too short: a 2 KB file
whose chunk length reads 0xFFFFFFF0 took 4.2 GB and 3 to 13 s in ``cv2.imread``. The formats Pillow cannot
read that OpenCV decodes (PAM, PFM, Radiance HDR, and TIFF and JPEG layouts Pillow refuses:
float samples, 12-bit) have their size read here too, so that every file decoded has had its
size checked first.
"""

from __future__ import annotations

import contextlib
import io
import re
import struct
import threading
import warnings
from typing import Any, Dict, Iterator, NamedTuple, Optional, Tuple

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
JPEG_SOI = b"\xff\xd8"
TIFF_SIGNATURES = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")  # classic, then BigTIFF
#: Signatures of formats whose header stands at the start of the file (GIF: the logical
#: screen; BMP: the info header; WebP: the first chunk; PAM, PFM and Radiance HDR: text
#: lines): one that cannot be read from the file's first bytes is not in the file.
HEADER_FIRST = (b"GIF87a", b"GIF89a", b"BM", b"RIFF", b"P7", b"PF", b"Pf", b"#?RADIANCE",
                b"#?RGBE")
#: The first bytes of the image files OpenCV decodes: a file that starts so and whose header
#: cannot be read is broken, not of another kind.
IMAGE_SIGNATURES = (PNG_SIGNATURE, JPEG_SOI) + TIFF_SIGNATURES + HEADER_FIRST

#: PNG colour types and the bit depths each allows (PNG specification, 11.2.2 IHDR): grey,
#: truecolour, indexed colour, grey with alpha, truecolour with alpha.
PNG_DEPTHS: Dict[int, Tuple[int, ...]] = {0: (1, 2, 4, 8, 16), 2: (8, 16), 3: (1, 2, 4, 8),
                                          4: (8, 16), 6: (8, 16)}
#: The largest chunk length the PNG specification allows, bytes (2^31 - 1).
PNG_MAX_CHUNK = 2**31 - 1
#: The longest side libpng decodes, px: its default user limit (PNG_USER_WIDTH_MAX and
#: PNG_USER_HEIGHT_MAX); a wider PNG is refused by libpng however it is made.
PNG_MAX_SIDE = 1_000_000
#: JPEG markers of a frame header (SOF0..SOF15 but DHT 0xC4, JPG 0xC8, DAC 0xCC): the size.
JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


class Header(NamedTuple):
    """What a file's header says, without decoding its pixels."""

    size: Optional[Tuple[int, int]]  #: (width, height) px as stored, None when not recognised
    orientation: int  #: EXIF orientation 1..8 (1: as stored)
    scan: int  #: JPEG: offset of the first scan (its pixel data); MPO: 0; else -1


class BadHeader(ValueError):
    """A header no decoder should be given: the message says what is wrong in it."""


def header(data: bytes) -> Header:
    """The header of an image file whose first bytes (or all of them) are ``data``.

    PNG is read here (:func:`png_header`); the other formats by Pillow, with its
    decompression-bomb guard lifted (the reader checks the size against its own limit right
    after: ``--max-pixels``); when Pillow does not know the file, by the readers of this module
    for TIFF, JPEG, PAM, PFM and Radiance HDR. ``size=None``: no header in ``data``.
    ``BadHeader`` for a header no decoder should be given: a PNG header the specification does
    not allow (:func:`png_header`), a JPEG frame header without a size (:func:`jpeg_header`).

    >>> import cv2, numpy as np
    >>> png = cv2.imencode(".png", np.zeros((30, 40), np.uint8))[1].tobytes()
    >>> header(png)
    Header(size=(40, 30), orientation=1, scan=-1)
    >>> header(png[:24] + bytes([0, 255]) + png[26:])  # bit depth 0, colour type 255
    Traceback (most recent call last):
    ...
    scalematch.headers.BadHeader: PNG header is invalid: bit depth 0 with colour type 255 (the standard allows colour types 0, 2, 3, 4 and 6)
    """
    if data.startswith(PNG_SIGNATURE):
        return png_header(data) or Header(None, 1, -1)
    read = _pillow_header(data)
    if read.size is not None:
        return read
    for reader in (tiff_header, jpeg_header, text_header):
        found = reader(data)
        if found is not None:
            return found
    return read


# --------------------------------------------------------------------------- Pillow

#: Pillow's decompression-bomb guard is module state (``PIL.Image.MAX_IMAGE_PIXELS``): lifted
#: while a header is read, one thread at a time, and set back.
_PILLOW_GUARD = threading.Lock()


@contextlib.contextmanager
def _pillow_unguarded() -> Iterator[None]:
    """Pillow's decompression-bomb guard lifted: it refuses images above twice
    ``PIL.Image.MAX_IMAGE_PIXELS`` (179 MP), whatever ``--max-pixels`` allows, and in words
    that do not say the image's size. Only the header is read meanwhile, no pixel."""
    from PIL import Image

    with _PILLOW_GUARD:
        saved = Image.MAX_IMAGE_PIXELS
        Image.MAX_IMAGE_PIXELS = None
        try:
            yield
        finally:
            Image.MAX_IMAGE_PIXELS = saved


class _NotWhileReading:
    """Drops Pillow's log records in a thread that is reading a header here (``_READING``): a
    logging filter (any object with this method is one), not a ``logging.Filter``, so that
    ``logging`` loads only when Pillow does."""

    def filter(self, record: Any) -> bool:
        return not (getattr(_READING, "header", False) and record.name.split(".")[0] == "PIL")


#: Which threads are reading a header with Pillow (``_READING.header``).
_READING = threading.local()
_QUIET_PILLOW = _NotWhileReading()


@contextlib.contextmanager
def _pillow_unlogged() -> Iterator[None]:
    """Pillow's log records of the block not said on stderr. Pillow logs an error as it gives
    up on a TIFF with more samples per pixel than it decodes ("More samples per pixel than can
    be decoded: 16003"), and Python's logging says a record on stderr when the program set up
    no logging (``logging.lastResort``): here, that Pillow cannot read a header only means the
    readers of this module are tried next. The records still reach the handlers a program set
    up; only the last resort drops them, and only those of the thread reading."""
    import logging

    if logging.lastResort is not None:
        logging.lastResort.addFilter(_QUIET_PILLOW)  # once: a filter is added only once
    _READING.header = True
    try:
        yield
    finally:
        _READING.header = False


def _pillow_header(data: bytes) -> Header:
    from PIL import Image  # imported when a file is read (40-46 ms), not with scalematch

    with warnings.catch_warnings(), _pillow_unguarded(), _pillow_unlogged():
        warnings.simplefilter("ignore")  # Pillow warns about corrupt EXIF
        try:
            with Image.open(io.BytesIO(data)) as im:
                size = (int(im.size[0]), int(im.size[1]))
                orientation = _orientation(im)
                scan = int(im.tile[0][2]) if im.format == "JPEG" and im.tile else -1
                if im.format == "MPO":  # JPEG images in a row (drones, some cameras): OpenCV
                    scan = 0            # decodes the first; where its scan starts is not kept
        except Exception:  # noqa: BLE001 (untrusted bytes: any failure means "not recognised")
            return Header(None, 1, -1)
    return Header(size, orientation, scan)


def _orientation(im) -> int:
    """The EXIF Orientation tag (0x0112) of an opened ``PIL.Image``, from the header only
    (``im.getexif()`` may decode a PNG to find it)."""
    if "exif" in im.info:
        return exif_orientation(im.info["exif"])
    try:
        value = int(getattr(im, "tag_v2", {}).get(0x0112, 1))  # TIFF: a tag of its own IFD
    except Exception:  # noqa: BLE001 (a corrupt tag: shown as stored)
        return 1
    return value if 1 <= value <= 8 else 1


def exif_orientation(block: bytes) -> int:
    """The Orientation tag (0x0112) of an EXIF block (with or without its ``Exif\\0\\0``
    prefix), read by Pillow; 1 (as stored) when it is missing or the block is corrupt."""
    from PIL import Image

    try:
        exif = Image.Exif()
        exif.load(bytes(block))
        value = int(exif.get(0x0112, 1))
    except Exception:  # noqa: BLE001 (a corrupt EXIF block: shown as stored)
        return 1
    return value if 1 <= value <= 8 else 1


# --------------------------------------------------------------------------- PNG

def png_ihdr_problems(width: int, height: int, depth: int, colour: int, compression: int,
                      filtering: int, interlace: int) -> list:
    """What is wrong with the fields of a PNG's IHDR chunk, as the specification and libpng
    take them; empty when nothing.

    >>> png_ihdr_problems(419, 256, 8, 2, 0, 0, 0)
    []
    >>> png_ihdr_problems(8388352, 1, 0, 0, 0, 0, 0)
    ['width 8388352 px, above the 1000000 px libpng decodes', 'bit depth 0 with colour type 0 (allowed: 1, 2, 4, 8, 16)']
    """
    out = []
    for name, side in (("width", width), ("height", height)):
        if side == 0:
            out.append(f"{name} 0")
        elif side > PNG_MAX_SIDE:
            out.append(f"{name} {side} px, above the {PNG_MAX_SIDE} px libpng decodes")
    if colour not in PNG_DEPTHS:
        out.append(f"bit depth {depth} with colour type {colour} (the standard allows colour "
                   f"types 0, 2, 3, 4 and 6)")
    elif depth not in PNG_DEPTHS[colour]:
        out.append(f"bit depth {depth} with colour type {colour} (allowed: "
                   f"{', '.join(map(str, PNG_DEPTHS[colour]))})")
    for name, value, allowed in (("compression method", compression, (0,)),
                                 ("filter method", filtering, (0,)),
                                 ("interlace method", interlace, (0, 1))):
        if value not in allowed:
            out.append(f"{name} {value}")
    return out


def png_header(data: bytes) -> Optional[Header]:
    """The header of a PNG file whose first bytes are ``data``: the size from its IHDR chunk,
    the orientation from an eXIf chunk before the image data (IDAT; Pillow and OpenCV read
    none after it), without importing Pillow unless there is one (40 ms of a whole process,
    measured with ``python -X importtime``). None when ``data`` holds no IHDR chunk first, or
    ends before the first IDAT chunk. ``BadHeader`` for an IHDR chunk the specification does
    not allow, or one libpng refuses (a side above ``PNG_MAX_SIDE``).
    """
    if len(data) < 33 or data[12:16] != b"IHDR":
        return None
    if int.from_bytes(data[8:12], "big") != 13:
        raise BadHeader(f"PNG header is invalid: its IHDR chunk holds "
                        f"{int.from_bytes(data[8:12], 'big')} bytes, not 13")
    fields = struct.unpack(">IIBBBBB", data[16:29])
    problems = png_ihdr_problems(*fields)
    if problems:
        raise BadHeader(f"PNG header is invalid: {'; '.join(problems)}")
    orientation, pos = 1, 33
    while pos + 8 <= len(data):
        n, kind = int.from_bytes(data[pos:pos + 4], "big"), data[pos + 4:pos + 8]
        if kind == b"IDAT":
            return Header(fields[:2], orientation, -1)
        if kind == b"eXIf":
            if pos + 8 + n > len(data):
                return None  # more is needed
            orientation = exif_orientation(b"Exif\x00\x00" + data[pos + 8:pos + 8 + n])
        pos += 12 + n  # length, type, data, CRC
    return None


def png_chunk_problem(data: bytes) -> str:
    """What is wrong with the chunks of the whole PNG file ``data``, or "" when they run, each
    within the specification's length, from the signature to an IEND chunk inside the file.
    Every chunk is read by OpenCV into a buffer of the length its header states: this is
    checked before it is.

    >>> ok = PNG_SIGNATURE + bytes(4) + b"IEND" + bytes(4)
    >>> png_chunk_problem(ok), png_chunk_problem(ok[:-2])
    ('', 'PNG file is truncated (no IEND chunk)')
    """
    pos = len(PNG_SIGNATURE)
    while pos + 12 <= len(data):
        n = int.from_bytes(data[pos:pos + 4], "big")
        end = pos + 12 + n
        if n > PNG_MAX_CHUNK or (end > len(data) and data.rfind(b"IEND") > pos):
            return (f"PNG file is corrupt: a chunk at byte {pos} says it holds {n} bytes, "
                    f"{'more than the standard allows' if n > PNG_MAX_CHUNK else 'past the end of the file'}")
        if data[pos + 4:pos + 8] == b"IEND":
            return ""
        pos = end
    return "PNG file is truncated (no IEND chunk)"


# --------------------------------------------------------------------------- JPEG

def jpeg_segments(data: bytes) -> Iterator[Tuple[int, int, int]]:
    """(offset, marker, length field) of each marker segment of the JPEG file whose first bytes
    are ``data``, after its SOI marker, up to the first scan (SOS) or the end (EOI) included,
    or up to the end of ``data``; marker -1 where a byte stands that begins no marker (a broken
    file), and nothing after it.

    >>> list(jpeg_segments(b"\\xff\\xd8\\xff\\xe0\\x00\\x04ab\\xff\\xda\\x00\\x02"))
    [(2, 224, 4), (8, 218, 2)]
    """
    pos = 2
    while pos + 4 <= len(data):
        if data[pos] != 0xFF:
            yield pos, -1, 0
            return
        marker = data[pos + 1]
        if marker == 0xFF:  # a fill byte
            pos += 1
            continue
        length = int.from_bytes(data[pos + 2:pos + 4], "big")
        yield pos, marker, length
        if marker in (0xD9, 0xDA) or length < 2:
            return
        pos += 2 + length


def jpeg_header(data: bytes) -> Optional[Header]:
    """The header of a JPEG file Pillow does not read (a 12-bit one, say): the size from its
    frame header (SOF), the orientation from an EXIF block before it; None when ``data`` does
    not reach the frame header. ``BadHeader`` for a frame header no decoder can use: a height
    of 0 (given later by a DNL marker, which libjpeg does not support), no components or more
    than 4."""
    if not data.startswith(JPEG_SOI):
        return None
    orientation, size = 1, None
    for pos, marker, length in jpeg_segments(data):
        if marker in (-1, 0xD9) or length < 2:
            return None
        body = data[pos + 4:pos + 2 + length]
        if marker == 0xE1 and body.startswith(b"Exif\x00\x00"):
            orientation = exif_orientation(body)
        elif marker in JPEG_SOF and size is None:
            if len(body) < 6:
                return None
            height, width, components = (int.from_bytes(body[1:3], "big"),
                                         int.from_bytes(body[3:5], "big"), body[5])
            if height == 0 or width == 0 or not 1 <= components <= 4:
                raise BadHeader(f"JPEG header is invalid: it says {width}x{height} px and "
                                f"{components} colour "
                                f"{'component' if components == 1 else 'components'}")
            size = (width, height)
        elif marker == 0xDA:
            return Header(size, orientation, pos) if size is not None else None
    return None


def header_may_follow(prefix: bytes) -> bool:
    """Whether a file whose header could not be read from ``prefix`` (its first bytes) may
    hold one further on, so that reading on is worth it.

    No for a PNG without its IHDR chunk first, for the formats of ``HEADER_FIRST`` (their
    header comes first), and for a JPEG whose segments before the frame header break off or
    end inside ``prefix``; yes for a JPEG whose segments run on past ``prefix`` (large EXIF,
    ICC, XMP blocks), for a PNG whose chunks before its image data do (long text chunks),
    and for any other format (a TIFF's directory may stand anywhere).

    >>> header_may_follow(b"\\x89PNG\\r\\n\\x1a\\n" + bytes(100))
    False
    >>> header_may_follow(b"\\xff\\xd8\\xff\\xe1\\xff\\xfe" + bytes(100))  # APP1 of 65534 bytes
    True
    """
    if prefix.startswith(PNG_SIGNATURE):
        return prefix[12:16] == b"IHDR"
    if prefix.startswith(HEADER_FIRST):
        return False
    if prefix.startswith(JPEG_SOI):
        # the frame header (or the end) is there yet was not read; or the file is broken
        return not any(marker == -1 or marker in JPEG_SOF or marker in (0xD9, 0xDA)
                       or length < 2 for _, marker, length in jpeg_segments(prefix))
    return True


# --------------------------------------------------------------------------- TIFF

#: TIFF field types of an integer value: type -> (struct code, bytes)
_TIFF_INTEGERS = {1: ("B", 1), 3: ("H", 2), 4: ("I", 4), 16: ("Q", 8)}


def tiff_header(data: bytes) -> Optional[Header]:
    """The header of a TIFF file Pillow does not read (float or multi-sample layouts): the
    size and orientation tags of its first directory (classic TIFF or BigTIFF); None when
    ``data`` does not hold that directory or its size tags."""
    if not data.startswith(TIFF_SIGNATURES):
        return None
    order = "<" if data[:2] == b"II" else ">"
    big = data[2:4] in (b"+\x00", b"\x00+")
    try:
        if big:
            ifd = struct.unpack_from(order + "Q", data, 8)[0]
            count = struct.unpack_from(order + "Q", data, ifd)[0]
            first, step, value_at, count_code = ifd + 8, 20, 12, "Q"
        else:
            ifd = struct.unpack_from(order + "I", data, 4)[0]
            count = struct.unpack_from(order + "H", data, ifd)[0]
            first, step, value_at, count_code = ifd + 2, 12, 8, "I"
        tags: Dict[int, int] = {}
        for k in range(min(count, 4096)):
            at = first + step * k
            tag, kind = struct.unpack_from(order + "HH", data, at)
            if tag in (256, 257, 274) and kind in _TIFF_INTEGERS:
                n = struct.unpack_from(order + count_code, data, at + 4)[0]
                code, _ = _TIFF_INTEGERS[kind]
                if n >= 1:
                    tags[tag] = struct.unpack_from(order + code, data, at + value_at)[0]
    except struct.error:  # the directory is not within ``data``
        return None
    if 256 not in tags or 257 not in tags:
        return None
    orientation = tags.get(274, 1)
    return Header((tags[256], tags[257]), orientation if 1 <= orientation <= 8 else 1, -1)


#: Most pages (image file directories) of a TIFF counted by :func:`tiff_pages`: a chain of them
#: is followed one offset at a time, and a hostile file's chain may be as long as the file has
#: room for 6-byte directories; a real stack of pages (a scan, a microscope series) has fewer
MAX_TIFF_PAGES = 10_000


def tiff_pages(data: bytes) -> int:
    """The pages of the TIFF file whose bytes are ``data`` (a ``bytes``-like: an ``mmap`` of the
    file will do): its image file directories, following the chain of next-directory offsets
    from the first, classic TIFF or BigTIFF. The walk stops at a 0 offset (the last page), at a
    directory seen before (a loop), at one not within ``data``, or at ``MAX_TIFF_PAGES``. 0 when
    ``data`` is no TIFF. OpenCV decodes the first page only.

    >>> one = struct.pack("<HI", 0, 0)  # a directory of no entry, and no next one
    >>> tiff_pages(b"II*\\x00" + struct.pack("<IHI", 8, 0, 14) + one)
    2
    >>> tiff_pages(b"II*\\x00" + struct.pack("<IHI", 8, 0, 8))  # a loop
    1
    """
    if bytes(data[:4]) not in TIFF_SIGNATURES:
        return 0
    order = "<" if bytes(data[:2]) == b"II" else ">"
    big = bytes(data[2:4]) in (b"+\x00", b"\x00+")
    offset, count, entry = ("Q", "Q", 20) if big else ("I", "H", 12)
    seen = set()
    try:
        at = struct.unpack_from(order + offset, data, 8 if big else 4)[0]
        while at and at not in seen and len(seen) < MAX_TIFF_PAGES:
            n = struct.unpack_from(order + count, data, at)[0]
            after = struct.unpack_from(order + offset, data,
                                       at + struct.calcsize(count) + entry * n)[0]
            seen.add(at)
            at = after
    except (struct.error, OverflowError):  # a directory not within ``data``: the pages before
        pass
    return len(seen)


# --------------------------------------------------------------------------- text headers

#: The size line of a Radiance HDR file: "-Y 480 +X 640" (rows first) or "+X 640 -Y 480".
_HDR_SIZE = re.compile(rb"^([-+])([XY]) (\d+) ([-+])([XY]) (\d+)$")


def text_header(data: bytes) -> Optional[Header]:
    """The size of a PAM (``P7``), PFM (``PF``, ``Pf``) or Radiance HDR (``#?RADIANCE``,
    ``#?RGBE``) file, from its text header; None for another file, or when ``data`` ends
    before the size."""
    head = bytes(data[:4096])
    if head.startswith(b"P7"):
        fields = dict(re.findall(rb"^(WIDTH|HEIGHT)\s+(\d+)\s*$", head, re.M))
        if b"WIDTH" in fields and b"HEIGHT" in fields:
            return Header((int(fields[b"WIDTH"]), int(fields[b"HEIGHT"])), 1, -1)
    elif head.startswith((b"PF", b"Pf")):
        tokens = head[2:].split(None, 3)
        if len(tokens) >= 3 and tokens[0].isdigit() and tokens[1].isdigit():
            return Header((int(tokens[0]), int(tokens[1])), 1, -1)
    elif head.startswith((b"#?RADIANCE", b"#?RGBE")):
        _, blank, rest = head.partition(b"\n\n")
        found = _HDR_SIZE.match(rest.split(b"\n", 1)[0]) if blank else None
        if found:
            sides = {found.group(2): int(found.group(3)), found.group(5): int(found.group(6))}
            if set(sides) == {b"X", b"Y"}:
                return Header((sides[b"X"], sides[b"Y"]), 1, -1)
    return None
