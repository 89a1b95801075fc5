"""A seeded corpus of hostile image files: the demo image in five formats, mutated.

The reader (:mod:`scalematch.imageio`) takes image files as untrusted input. This corpus is
what it is tested against (``tests/test_fuzz.py``) and measured on (``scripts/fuzz_inputs.py``):
``data/demo_low.png`` shrunk to ``BASE_SIZE`` and written as PNG, JPEG, TIFF, BMP and WebP, and
each file mutated in five ways (``KINDS``), ``PER_KIND`` times each, from one seed:

* ``flip``: a few bytes anywhere set to random values;
* ``header``: the fields of the header set to random values (a PNG's IHDR with its CRC
  made right again, so that the decoder reads the values rather than refusing the CRC): bit
  depth 0 with colour type 255 and the like;
* ``truncate``: the file cut short, at a random length;
* ``repeat``: a part repeated: a PNG chunk or a JPEG segment, a block of bytes elsewhere;
* ``huge``: a size field set to a huge value: the width, the height, a PNG chunk's length, a
  BMP's bits per pixel, a TIFF's strip size, a RIFF size.

The same seed gives the same files with the same OpenCV (which encodes the five originals).
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path
from typing import Callable, Dict, Iterator, List, NamedTuple, Tuple

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
#: The image mutated: the demo pair's coarser image, shipped in the repository.
SOURCE = ROOT / "data" / "demo_low.png"
#: (width, height) of the originals, px: small, so that a mutant that still decodes is matched
#: quickly, and above the 24 px a side the matcher needs.
BASE_SIZE = (160, 144)
#: The formats written, by extension; OpenCV writes each.
FORMATS = ("png", "jpg", "tif", "bmp", "webp")
KINDS = ("flip", "header", "truncate", "repeat", "huge")
#: Mutants of each kind and format: 5 x 5 x 10 = 250 files.
PER_KIND = 10
#: Values a huge size field is given: the 32-bit and 16-bit extremes, and the two PNG headers
#: that made OpenCV allocate 4.2 GB (8388352 x 1 px).
HUGE = (0xFFFFFFFF, 0x7FFFFFFF, 0x80000000, 0xFFFF, 0x10000, 8388352, 0xFFFFFF00, 0)


class Mutant(NamedTuple):
    """One file of the corpus."""

    name: str  #: ``{format}-{kind}-{k}.{format}``
    data: bytes


def originals(size: Tuple[int, int] = BASE_SIZE) -> Dict[str, bytes]:
    """The unmutated files by extension: ``SOURCE`` shrunk to ``size``, in colour."""
    img = cv2.imread(str(SOURCE), cv2.IMREAD_COLOR)
    img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    out = {}
    for ext in FORMATS:
        ok, buf = cv2.imencode("." + ext, img)
        if not ok:
            raise RuntimeError(f"OpenCV cannot write .{ext}")
        out[ext] = buf.tobytes()
    return out


# --------------------------------------------------------------------------- the parts of a file

def png_chunks(data: bytes) -> List[Tuple[int, int]]:
    """(offset, total length) of each chunk of a PNG file: length, type, data and CRC."""
    out, pos = [], 8
    while pos + 12 <= len(data):
        n = int.from_bytes(data[pos:pos + 4], "big")
        out.append((pos, 12 + n))
        if data[pos + 4:pos + 8] == b"IEND":
            break
        pos += 12 + n
    return out


def fix_png_crc(data: bytearray, pos: int) -> None:
    """Make the CRC of the PNG chunk at ``pos`` right again."""
    n = int.from_bytes(data[pos:pos + 4], "big")
    end = pos + 8 + n
    if end + 4 <= len(data):
        data[end:end + 4] = zlib.crc32(bytes(data[pos + 4:end])).to_bytes(4, "big")


def jpeg_segments(data: bytes) -> List[Tuple[int, int]]:
    """(offset, total length) of each marker segment before the first scan's data (SOS
    included), after the SOI marker."""
    out, pos = [], 2
    while pos + 4 <= len(data) and data[pos] == 0xFF:
        marker = data[pos + 1]
        n = int.from_bytes(data[pos + 2:pos + 4], "big")
        out.append((pos, 2 + n))
        if marker == 0xDA:
            break
        pos += 2 + n
    return out


def jpeg_sof(data: bytes) -> int:
    """Offset of the frame header's (SOF0..SOF15) marker, or -1."""
    for pos, _ in jpeg_segments(data):
        m = data[pos + 1]
        if 0xC0 <= m <= 0xCF and m not in (0xC4, 0xC8, 0xCC):
            return pos
    return -1


def tiff_entries(data: bytes) -> List[Tuple[int, int, int]]:
    """(offset of the entry, tag, type) of each entry of a TIFF file's first directory."""
    order = "<" if data[:2] == b"II" else ">"
    ifd = struct.unpack(order + "I", data[4:8])[0]
    if ifd + 2 > len(data):
        return []
    n = struct.unpack(order + "H", data[ifd:ifd + 2])[0]
    out = []
    for k in range(n):
        pos = ifd + 2 + 12 * k
        if pos + 12 > len(data):
            break
        tag, typ = struct.unpack(order + "HH", data[pos:pos + 4])
        out.append((pos, tag, typ))
    return out


def header_fields(data: bytes, ext: str) -> List[Tuple[int, int]]:
    """(offset, width in bytes) of the fields of a file's header that a decoder reads first: the
    size, depth, colour layout, compression; big-endian for PNG and JPEG."""
    if ext == "png":  # IHDR: width, height, bit depth, colour type, compression, filter, interlace
        return [(16, 4), (20, 4), (24, 1), (25, 1), (26, 1), (27, 1), (28, 1)]
    if ext == "jpg":  # SOF: precision, height, width, components, then each component's sampling
        sof = jpeg_sof(data)
        return [(sof + 4, 1), (sof + 5, 2), (sof + 7, 2), (sof + 9, 1), (sof + 11, 1),
                (sof + 12, 1)] if sof >= 0 else []
    if ext == "bmp":  # the info header: width, height, planes, bits per pixel, compression, ...
        return [(18, 4), (22, 4), (26, 2), (28, 2), (30, 4), (34, 4), (46, 4)]
    if ext == "tif":  # the value of each entry of the first directory
        return [(pos + 8, 4) for pos, _, _ in tiff_entries(data)]
    if ext == "webp":  # RIFF size, then the first chunk: its size and the frame's header
        return [(4, 4), (16, 4), (20, 4), (24, 2), (26, 2), (28, 2)]
    return []


# --------------------------------------------------------------------------- the mutations

def flip(data: bytes, ext: str, rng: np.random.Generator) -> bytes:
    """1 to 8 bytes anywhere after the signature set to random values."""
    out = bytearray(data)
    for _ in range(int(rng.integers(1, 9))):
        out[int(rng.integers(4, len(out)))] = int(rng.integers(0, 256))
    return bytes(out)


def header(data: bytes, ext: str, rng: np.random.Generator) -> bytes:
    """1 to 3 fields of the header (:func:`header_fields`) set to random values; a PNG's IHDR
    CRC made right again."""
    out = bytearray(data)
    fields = header_fields(data, ext)
    for k in rng.choice(len(fields), size=min(len(fields), int(rng.integers(1, 4))),
                        replace=False):
        pos, width = fields[int(k)]
        value = int(rng.integers(0, 256 ** width)) if rng.random() < 0.5 else \
            int(rng.choice([0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 32, 64, 255]))
        out[pos:pos + width] = (value % 256 ** width).to_bytes(width, "little" if ext in
                                                               ("bmp", "webp") else "big")
    if ext == "png":
        fix_png_crc(out, 8)
    return bytes(out)


def truncate(data: bytes, ext: str, rng: np.random.Generator) -> bytes:
    """The file cut at a random length: within its first 2 KB half the time."""
    end = int(rng.integers(1, min(2048, len(data)))) if rng.random() < 0.5 else \
        int(rng.integers(1, len(data)))
    return data[:end]


def repeat(data: bytes, ext: str, rng: np.random.Generator) -> bytes:
    """A part repeated 2 to 50 times: a PNG chunk, a JPEG segment, a block of 16 to 512 bytes
    of the other formats."""
    parts = png_chunks(data) if ext == "png" else jpeg_segments(data) if ext == "jpg" else []
    if parts:
        pos, n = parts[int(rng.integers(0, len(parts)))]
    else:
        n = int(rng.integers(16, 513))
        pos = int(rng.integers(0, max(1, len(data) - n)))
    times = int(rng.integers(2, 51))
    return data[:pos] + data[pos:pos + n] * times + data[pos + n:]


def huge(data: bytes, ext: str, rng: np.random.Generator) -> bytes:
    """A size field (:func:`header_fields`' first two, a PNG chunk's length, a TIFF entry's
    value) set to one of ``HUGE``; the other dimension set to 1 half the time (the 8388352 x
    1 px PNG)."""
    out = bytearray(data)
    value = int(rng.choice(HUGE))
    fields = header_fields(data, ext)
    if ext == "png" and rng.random() < 0.5:  # the length of a chunk after IHDR: OpenCV
        chunks = png_chunks(data)[1:]         # reads those before the pixels itself
        pos, _ = chunks[0 if rng.random() < 0.5 else int(rng.integers(0, len(chunks)))]
        out[pos:pos + 4] = value.to_bytes(4, "big")
        return bytes(out)
    if ext == "tif":
        entries = tiff_entries(data)
        pos = entries[int(rng.integers(0, len(entries)))][0] + 8 if entries else 4
        out[pos:pos + 4] = value.to_bytes(4, "little" if data[:2] == b"II" else "big")
        return bytes(out)
    if ext == "jpg":
        fields = fields[1:3]  # height, width
    elif ext == "webp":
        fields = [(4, 4), (16, 4)] if rng.random() < 0.5 else [(26, 2), (28, 2)]
    else:
        fields = fields[:2]  # width, height
    order = "little" if ext in ("bmp", "webp") else "big"
    k = int(rng.integers(0, len(fields)))
    for j, (pos, width) in enumerate(fields):
        if j == k:
            out[pos:pos + width] = (value % 256 ** width).to_bytes(width, order)
        elif rng.random() < 0.5:
            out[pos:pos + width] = (1).to_bytes(width, order)
    if ext == "png":
        fix_png_crc(out, 8)
    return bytes(out)


MUTATIONS: Dict[str, Callable[[bytes, str, np.random.Generator], bytes]] = {
    "flip": flip, "header": header, "truncate": truncate, "repeat": repeat, "huge": huge}


def corpus(seed: int = 0, per_kind: int = PER_KIND) -> Iterator[Mutant]:
    """The mutants of every original (:func:`originals`), ``per_kind`` of each kind: the same
    files for the same ``seed``."""
    rng = np.random.default_rng(seed)
    for ext, data in originals().items():
        for kind in KINDS:
            for k in range(per_kind):
                yield Mutant(f"{ext}-{kind}-{k}.{ext}", MUTATIONS[kind](data, ext, rng))


def write_corpus(folder: Path, seed: int = 0, per_kind: int = PER_KIND) -> List[Path]:
    """Write :func:`corpus` into ``folder`` (created); the paths, in the corpus's order."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for m in corpus(seed, per_kind):
        path = folder / m.name
        path.write_bytes(m.data)
        paths.append(path)
    return paths
