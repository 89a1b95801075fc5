"""imageio: every layout gives the same grey, EXIF orientation is applied, bad files say why."""

from __future__ import annotations

import io
import struct
import warnings
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from PIL import Image

from scalematch.greylevels import to_grey
from scalematch.headers import header
from scalematch.imagefile import DEFAULT_MAX_PIXELS, ImageError
from scalematch.imageio import (ImageWarning, decoder_stderr_caught, read_grey, read_image,
                                read_reduced)

ROOT = Path(__file__).resolve().parents[1]


def exif_app1(orientation: int, little_endian: bool = False) -> bytes:
    """A minimal EXIF APP1 segment holding only the Orientation tag, built by hand."""
    e = "<" if little_endian else ">"
    tiff = (b"II*\x00" if little_endian else b"MM\x00*") + struct.pack(e + "I", 8)
    tiff += struct.pack(e + "H", 1) + struct.pack(e + "HHIHH", 0x0112, 3, 1, orientation, 0)
    tiff += struct.pack(e + "I", 0)
    payload = b"Exif\x00\x00" + tiff
    return b"\xff\xe1" + struct.pack(">H", len(payload) + 2) + payload


def jpeg_bytes(img: np.ndarray, orientation: int = 0, little_endian: bool = False) -> bytes:
    data = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 95])[1].tobytes()
    if orientation:
        data = data[:2] + exif_app1(orientation, little_endian) + data[2:]
    return data


def write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def test_grey_colour_rgba_16bit_agree(tmp_path, bgr):
    ref = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    colour = tmp_path / "colour.png"
    cv2.imwrite(str(colour), bgr)
    grey = tmp_path / "grey.png"
    cv2.imwrite(str(grey), cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY))
    rgba = tmp_path / "rgba.png"
    alpha = np.full(bgr.shape[:2] + (1,), 37, np.uint8)  # alpha is ignored
    cv2.imwrite(str(rgba), np.concatenate([bgr, alpha], axis=2))
    deep = tmp_path / "deep.png"
    cv2.imwrite(str(deep), bgr.astype(np.uint16) * 257)
    deep_tif = tmp_path / "deep.tif"
    cv2.imwrite(str(deep_tif), cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.uint16) * 257)
    assert read_image(deep).dtype == np.uint16
    for path in (colour, grey, rgba, deep, deep_tif):
        g = read_grey(path)
        assert g.dtype == np.float32 and g.shape == ref.shape, path.name
        np.testing.assert_allclose(g, ref, atol=1.0, err_msg=path.name)


@pytest.mark.parametrize("little_endian", [False, True])
def test_exif_orientation_6_is_rotated_upright(tmp_path, bgr, little_endian):
    plain = read_grey(write(tmp_path / "plain.jpg", jpeg_bytes(bgr)))
    rotated = read_grey(write(tmp_path / "rot.jpg", jpeg_bytes(bgr, 6, little_endian)))
    assert rotated.shape == (bgr.shape[1], bgr.shape[0])
    # orientation 6: the stored picture must be turned 90 degrees clockwise to show upright
    np.testing.assert_allclose(rotated, np.rot90(plain, k=-1), atol=0.5)


@pytest.mark.parametrize("orientation", range(1, 9))
def test_exif_orientations_agree_with_opencv(tmp_path, bgr, orientation):
    data = jpeg_bytes(bgr, orientation)
    ours = read_image(write(tmp_path / "o.jpg", data))
    theirs = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if theirs.shape == bgr.shape and orientation >= 5:
        pytest.skip("this OpenCV build does not apply EXIF orientation in imdecode")
    np.testing.assert_array_equal(ours, theirs)


def test_header_size_before_decoding(tmp_path, bgr):
    for ext in (".png", ".jpg", ".bmp", ".tif", ".webp"):
        data = cv2.imencode(ext, bgr)[1].tobytes()
        assert header(data).size == (160, 120), ext
    assert header(b"this is not an image").size is None


def test_exif_orientation_of_a_png_is_applied_too(tmp_path, bgr):
    """Pillow reads the orientation of every format from the header, not only JPEG's."""
    exif = Image.Exif()
    exif[0x0112] = 6
    path = tmp_path / "rot.png"
    Image.fromarray(bgr[:, :, ::-1]).save(path, exif=exif.tobytes())
    assert header(path.read_bytes()).orientation == 6
    plain = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    np.testing.assert_allclose(read_grey(path), np.rot90(plain, k=-1), atol=1.0)


def test_pixel_limit_names_size_limit_and_option(tmp_path, bgr):
    path = tmp_path / "big.png"
    cv2.imwrite(str(path), bgr)
    with pytest.raises(ImageError) as err:
        read_grey(path, max_pixels=10_000)
    msg = str(err.value)
    assert "160x120" in msg and "0.01 MP" in msg and "--max-pixels" in msg and "\n" not in msg
    assert read_grey(path, max_pixels=DEFAULT_MAX_PIXELS).shape == (120, 160)


def png_header_only(width: int, height: int) -> bytes:
    """A PNG signature, a valid IHDR claiming width x height, then a scrap of pixel data."""
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", b"x" * 100)


def test_pixel_limit_checked_from_header_without_decoding(tmp_path):
    # a PNG header claiming 12000 x 12000 followed by garbage: refused for its size, not decoded
    limit = r"12000x12000 = 144.0 MP, above the limit of 100.0 MP \(100000000 px\)"
    with pytest.raises(ImageError, match=limit):
        read_grey(write(tmp_path / "bomb.png", png_header_only(12000, 12000)))
    # far past it too: the size and the option named, one line
    with pytest.raises(ImageError, match="50000x50000 = 2500.0 MP, above the limit") as err:
        read_grey(write(tmp_path / "bomb.png", png_header_only(50000, 50000)))
    assert "bomb.png" in str(err.value) and "--max-pixels" in str(err.value)
    assert "\n" not in str(err.value)


def jpeg_claiming(width: int, height: int) -> bytes:
    """A small JPEG whose frame header claims width x height px."""
    data = bytearray(cv2.imencode(".jpg", np.zeros((48, 64), np.uint8))[1].tobytes())
    sof = data.find(b"\xff\xc0")
    data[sof + 5:sof + 9] = struct.pack(">HH", height, width)
    return bytes(data)


def test_max_pixels_above_pillows_guard_takes_effect(tmp_path):
    """Pillow refuses headers above twice PIL.Image.MAX_IMAGE_PIXELS (179 MP) on its own: that
    guard is lifted while a header is read, so --max-pixels decides, above 179 MP too, and an
    image above the limit is told its size, not "shrink it" past a limit it did not set."""
    data = jpeg_claiming(20000, 10000)  # 200 MP
    assert header(data).size == (20000, 10000)
    assert Image.MAX_IMAGE_PIXELS == 89_478_485  # set back
    path = write(tmp_path / "pano.jpg", data)
    with pytest.raises(ImageError, match="20000x10000 = 200.0 MP, above the limit of 100.0 MP"):
        read_grey(path)
    with pytest.raises(ImageError, match="above the limit of 150.0 MP"):
        read_grey(path, max_pixels=150_000_000)


@pytest.fixture
def no_decoding(monkeypatch):
    """OpenCV's decoder replaced by one that fails the test: a file refused from its header
    is never handed to it."""
    def decode(*args):
        raise AssertionError("the decoder was called")

    monkeypatch.setattr(cv2, "imdecode", decode)


def png_with(data: bytes, width=None, height=None, depth=None, colour=None) -> bytes:
    """``data`` (a PNG file) with fields of its IHDR chunk replaced, its CRC made right."""
    out = bytearray(data)
    for pos, fmt, value in ((16, ">I", width), (20, ">I", height), (24, ">B", depth),
                            (25, ">B", colour)):
        if value is not None:
            out[pos:pos + struct.calcsize(fmt)] = struct.pack(fmt, value)
    out[29:33] = struct.pack(">I", zlib.crc32(bytes(out[12:29])))
    return bytes(out)


def test_the_two_png_headers_that_took_4_gb_are_refused_before_decoding(tmp_path, no_decoding):
    """Two 2 KB PNG files made OpenCV allocate 4.2 GB for 10 s before it refused them: a header
    saying 419x256 px at bit depth 0 and colour type 255, and one saying 8388352 x 1 px at bit
    depth 0. Both are refused from their IHDR chunk, and a chunk whose length field runs past
    the file's end (what OpenCV allocates) is refused before OpenCV reads it."""
    demo = (ROOT / "data" / "demo_low.png").read_bytes()
    cases = {
        "depth0-colour255.png": (png_with(demo[:2048], height=256, depth=0, colour=255),
                                 "bit depth 0 with colour type 255"),
        "wide.png": (png_with(demo[:2048], width=8388352, height=1, depth=0),
                     "width 8388352 px, above the 1000000 px libpng decodes"),
    }
    chunk = bytearray(demo)
    chunk[33:37] = struct.pack(">I", 0xFFFFFFF0)  # the first chunk after IHDR
    cases["chunk.png"] = (bytes(chunk), "a chunk at byte 33 says it holds 4294967280 bytes")
    chunk[33:37] = struct.pack(">I", 0x7FFFFFF0)
    cases["chunk2.png"] = (bytes(chunk), "past the end of the file")
    for name, (data, needle) in cases.items():
        path = write(tmp_path / name, data)
        with pytest.raises(ImageError, match=needle) as err:
            read_grey(path)
        assert str(err.value).startswith(f"{path}: ") and "\n" not in str(err.value), name


def test_png_bit_depths_and_colour_types_as_the_standard_allows():
    from scalematch.headers import PNG_DEPTHS, BadHeader

    base = png_header_only(64, 48)
    for colour in range(256):
        for depth in range(33):
            data = png_with(base, depth=depth, colour=colour)
            if depth in PNG_DEPTHS.get(colour, ()):
                assert header(data).size == (64, 48)
            else:
                with pytest.raises(BadHeader, match=f"bit depth {depth} with colour type "
                                                    f"{colour}"):
                    header(data)


def test_sizes_refused_from_the_header_before_decoding(tmp_path, no_decoding):
    """A side under the minimum, a side longer than the decoder takes, a size of 0: refused
    from the header of each format, not after OpenCV has decoded it."""
    thin = png_with(png_header_only(64, 48), width=100_000, height=3)
    cases = [("thin.png", thin, "100000x3, too small to match"),
             ("zero.jpg", jpeg_claiming(0, 48), "JPEG header is invalid: it says 0x48 px"),
             ("long.jpg", jpeg_claiming(65000, 20), "65000x20, too small"),
             ("huge.png", png_with(thin, width=1_000_001, height=24), "1000000 px libpng")]
    for name, data, needle in cases:
        with pytest.raises(ImageError, match=needle):
            read_grey(write(tmp_path / name, data))


def test_formats_pillow_cannot_read_have_their_size_read_here(tmp_path, bgr):
    """Float and 4-channel TIFF, PFM, PAM and Radiance HDR: Pillow does not read their headers,
    OpenCV decodes them. Their size comes from their header, so they are read as before; a
    header claiming more than the limit is refused without decoding."""
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    unit = bgr.astype(np.float32) / 255
    cases = {".tif": unit, ".pfm": unit, ".hdr": unit, ".pam": bgr}
    for ext, img in cases.items():
        data = cv2.imencode(ext, img)[1].tobytes()
        assert header(data).size == (160, 120), ext
        got = read_grey(write(tmp_path / f"img{ext}", data))
        assert got.shape == (120, 160), ext
        np.testing.assert_allclose(got, grey, atol=2.0, err_msg=ext)
    big = b"P7\nWIDTH 20000\nHEIGHT 20000\nDEPTH 3\nMAXVAL 255\nTUPLTYPE RGB\nENDHDR\n"
    with pytest.raises(ImageError, match="20000x20000 = 400.0 MP, above the limit"):
        read_grey(write(tmp_path / "big.pam", big + bytes(1000)))


def test_a_jpeg_pillow_refuses_has_its_size_read_from_its_frame_header():
    data = bytearray(jpeg_claiming(64, 48))
    data[data.find(b"\xff\xc0") + 4] = 12  # 12-bit samples: Pillow reads 8-bit JPEG only
    assert header(bytes(data)).size == (64, 48)


def test_the_pages_of_a_tiff_are_counted_as_opencv_counts_them(tmp_path):
    """Classic TIFF and BigTIFF of 3 pages, as OpenCV counts them; a chain of directories that
    loops, or points outside the file or past any file, ends the count; not a TIFF: 0."""
    from scalematch.headers import PNG_SIGNATURE, tiff_pages

    pages = [Image.fromarray(np.full((30, 40), 60 * k, np.uint8)) for k in range(3)]
    for big in (False, True):
        path = tmp_path / f"pages-{big}.tif"
        pages[0].save(path, "TIFF", save_all=True, append_images=pages[1:], big_tiff=big)
        data = path.read_bytes()
        assert data[2:3] == (b"+" if big else b"*")
        assert tiff_pages(data) == cv2.imcount(str(path)) == 3
    last = struct.pack("<HI", 0, 0)
    assert tiff_pages(b"II*\x00" + struct.pack("<IHI", 8, 0, 14) + last) == 2
    assert tiff_pages(b"MM\x00*" + struct.pack(">IHI", 8, 0, 8)) == 1  # back to itself
    assert tiff_pages(b"II*\x00" + struct.pack("<IHI", 8, 0, 999)) == 1  # beyond the file
    assert tiff_pages(b"II+\x00" + struct.pack("<HHQ", 8, 0, 2 ** 64 - 1)) == 0
    assert tiff_pages(b"II*") == tiff_pages(PNG_SIGNATURE) == 0


@pytest.mark.parametrize("case, needle", [
    ("missing", "no such file"),
    ("directory", "is a directory"),
    ("empty", "file is empty"),
    ("text", "not an image"),
    ("truncated_png", "truncated"),
    ("truncated_jpg", "truncated"),
    ("tiny", "too small"),
])
def test_bad_files_raise_one_line_image_error(tmp_path, bgr, case, needle):
    path = tmp_path / "img.png"
    if case == "directory":
        path.mkdir()
    elif case == "empty":
        path.write_bytes(b"")
    elif case == "text":
        path.write_text("this is not an image\n")
    elif case == "truncated_png":
        data = cv2.imencode(".png", bgr)[1].tobytes()
        path.write_bytes(data[: len(data) // 2])
    elif case == "truncated_jpg":
        path = tmp_path / "img.jpg"
        data = jpeg_bytes(bgr)
        path.write_bytes(data[: len(data) // 2])
    elif case == "tiny":
        cv2.imwrite(str(path), bgr[:20, :100])
    with pytest.raises(ImageError) as err:
        read_grey(path)
    msg = str(err.value)
    assert needle in msg and "\n" not in msg and str(path) in msg


def test_a_jpeg_cut_inside_its_metadata_is_called_truncated_not_unknown(tmp_path, bgr):
    """A camera JPEG cut before its frame header (inside a large EXIF block, so no size can be
    read) is a broken JPEG: the user is told to copy it again, not to give another format."""
    data = jpeg_bytes(bgr)
    app1 = b"\xff\xe1" + (60_000).to_bytes(2, "big") + b"Exif\x00\x00" + bytes(59_992)
    path = write(tmp_path / "cut.jpg", (data[:2] + app1 + data[2:])[:20_000])
    with pytest.raises(ImageError, match="truncated or corrupt"):
        read_grey(path)


def test_a_truncated_png_is_said_once_without_libpng_noise(tmp_path, bgr, capfd):
    data = cv2.imencode(".png", bgr)[1].tobytes()
    path = write(tmp_path / "cut.png", data[: len(data) // 2])
    with pytest.raises(ImageError, match="PNG file is truncated"):
        read_grey(path)
    assert capfd.readouterr().err == ""  # libpng's own "input buffer is incomplete" not run


def png_with_bad_idat_crc(img: np.ndarray) -> bytes:
    """``img`` as a PNG whose first image data chunk's CRC is wrong (its pixels intact)."""
    data = bytearray(cv2.imencode(".png", img)[1].tobytes())
    pos = 8
    while data[pos + 4:pos + 8] != b"IDAT":
        pos += 12 + int.from_bytes(data[pos:pos + 4], "big")
    end = pos + 8 + int.from_bytes(data[pos:pos + 4], "big")
    data[end] ^= 0xFF
    return bytes(data)


def jpeg_with_a_cut_scan(img: np.ndarray) -> bytes:
    """``img`` as a JPEG whose scan stops halfway, its end-of-image marker kept: libjpeg
    decodes it, the rest grey, saying "Corrupt JPEG data: premature end of data segment"."""
    data = jpeg_bytes(img)
    scan = data.rfind(b"\xff\xda")
    return data[:(scan + len(data)) // 2] + b"\xff\xd9"


def test_a_png_with_a_bad_crc_is_refused_in_one_line_quoting_libpng(tmp_path, bgr, capfd):
    """libpng refuses the file and says why on the process's stderr ("libpng error: IDAT: CRC
    error"). Where the decoders' words are caught: they come once, in the error naming the
    file, and nothing reaches stderr. By default (a library leaves its caller's stderr alone):
    the file is refused as corrupt, and libpng's line reaches stderr as libpng writes it."""
    path = write(tmp_path / "crc.png", png_with_bad_idat_crc(bgr))
    with decoder_stderr_caught(), pytest.raises(ImageError) as err:
        read_grey(path)
    assert str(err.value) == (f'{path}: cannot decode the image: the PNG decoder says "IDAT: CRC '
                              f'error"; the file is corrupt, copy or download it again')
    assert capfd.readouterr().err == ""
    with pytest.raises(ImageError) as err:
        read_grey(path)
    assert str(err.value) == (f"{path}: cannot decode the image (the file looks truncated or "
                              f"corrupt); copy or download it again")
    assert capfd.readouterr().err == "libpng error: IDAT: CRC error\n"


def test_a_damaged_jpeg_that_decodes_is_used_with_one_warning(tmp_path, bgr, capfd):
    """Where the decoders' words are caught: the same warning at full and at reduced size, as
    ``Decoded.warning`` and as an ``ImageWarning`` of read_grey; the image as libjpeg decodes
    it (the top intact, the rest grey); nothing from libjpeg on stderr. A truncated JPEG (no
    end-of-image marker) is still refused. By default: the same image, no warning of
    scalematch's, libjpeg's line on stderr as libjpeg writes it."""
    data = jpeg_with_a_cut_scan(bgr)
    path = write(tmp_path / "cut-scan.jpg", data)
    said = (f'{path}: the JPEG decoder says "Corrupt JPEG data: premature end of data segment"; '
            f'the image is used as decoded (copy or download the file again if it is damaged)')
    with decoder_stderr_caught():
        full, reduced = read_reduced(path, None), read_reduced(path, at_least=40)
        assert (full.factor, reduced.factor) == (1, 4)
        assert full.warning == reduced.warning == said
        with pytest.warns(ImageWarning) as caught:
            grey = read_grey(path)
        assert [str(w.message) for w in caught] == [said]
        assert caught[0].filename == __file__  # the warning points at the caller's line
        intact = to_grey(cv2.imdecode(np.frombuffer(jpeg_bytes(bgr), np.uint8),
                                      cv2.IMREAD_COLOR))
        assert np.abs(grey[:16] - intact[:16]).max() < 1.0  # the first row of blocks, as decoded
        assert read_reduced(write(tmp_path / "good.jpg", jpeg_bytes(bgr)), None).warning == ""
        with pytest.raises(ImageError, match="truncated"):
            read_grey(write(tmp_path / "truncated.jpg", data[:-2]))
    assert capfd.readouterr().err == ""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.array_equal(read_grey(path), grey)
    assert read_reduced(path, None).warning == ""
    assert capfd.readouterr().err == "Corrupt JPEG data: premature end of data segment\n" * 2


def test_threads_decoding_damaged_files_each_get_their_own_words(tmp_path, bgr, capfd):
    """Descriptor 2 belongs to the process: decodes in threads take it in turn, so each file
    gets what its own decoder said, and nothing leaks."""
    from concurrent.futures import ThreadPoolExecutor

    jpeg = write(tmp_path / "cut-scan.jpg", jpeg_with_a_cut_scan(bgr))
    png = write(tmp_path / "crc.png", png_with_bad_idat_crc(bgr))

    def said(path: Path) -> str:
        try:
            return read_reduced(path, None).warning
        except ImageError as exc:
            return str(exc)

    paths = [jpeg, png] * 40
    with decoder_stderr_caught(), ThreadPoolExecutor(4) as pool:
        out = list(pool.map(said, paths))
    for path, text in zip(paths, out):
        assert text.startswith(f"{path}: "), text
        assert ("premature end" in text) == (path == jpeg) and ("CRC" in text) == (path == png)
    assert capfd.readouterr().err == ""


#: A program using the library: a thread says its progress on descriptor 2 (numbered lines)
#: while the main thread reads damaged files, whose decoders write there too; then the number
#: of lines the thread wrote, on stdout.
TALKING_THREAD = """
import os, sys, threading, time, warnings
from scalematch import ImageError, read_grey

warnings.simplefilter("ignore")
done, said = threading.Event(), [0]

def talk():
    while not done.is_set():
        os.write(2, b"<progress %d>\\n" % said[0])
        said[0] += 1
        time.sleep(0.0001)

thread = threading.Thread(target=talk)
thread.start()
for _ in range(int(sys.argv[1])):
    for path in sys.argv[2:]:
        try:
            read_grey(path)
        except ImageError:
            pass
done.set()
thread.join()
print(said[0])
"""


def test_the_library_leaves_the_callers_stderr_alone(tmp_path):
    """By default a read does not take descriptor 2 from the process: every line another
    thread writes there while damaged files are read (which libpng and libjpeg talk about on
    stderr) reaches stderr, none caught and none lost."""
    import re
    import subprocess
    import sys

    demo = cv2.imread(str(ROOT / "data" / "demo_low.png"), cv2.IMREAD_COLOR)
    crc = write(tmp_path / "crc.png", png_with_bad_idat_crc(demo))
    cut = write(tmp_path / "cut-scan.jpg", jpeg_with_a_cut_scan(demo))
    run = subprocess.run([sys.executable, "-c", TALKING_THREAD, "60", crc, cut],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    written = int(run.stdout)
    arrived = [int(n) for n in re.findall(r"<progress (\d+)>", run.stderr)]
    assert written > 0 and arrived == list(range(written))
    assert run.stderr.count("IDAT: CRC error") == run.stderr.count("premature end of data") == 60


def test_the_command_line_says_a_decoders_words_once_in_its_own_voice(tmp_path, bgr):
    """In a process of its own (libpng and libjpeg write to descriptor 2, which CliRunner does
    not catch, and Python's logging says Pillow's records on stderr only where no logging is
    set up, as pytest sets it up): a PNG with a bad CRC, a TIFF of 16003 samples per pixel
    (which Pillow logs as it gives up) and a truncated JPEG are exit 2 with one "Error:" line
    naming the file; a JPEG whose scan is cut short is matched as decoded, silent under -q,
    its warning in the JSON (and in a batch line, matched here or by a worker process), one
    "Warning:" line without -q."""
    import json
    import subprocess
    import sys

    from scalematch.lab.fuzz import tiff_entries

    def cli(*args):
        return subprocess.run([sys.executable, "-m", "scalematch", *map(str, args)],
                              capture_output=True, text=True, timeout=120)

    high = ROOT / "data" / "demo_high.png"
    demo = cv2.imread(str(ROOT / "data" / "demo_low.png"), cv2.IMREAD_COLOR)
    crc = write(tmp_path / "crc.png", png_with_bad_idat_crc(demo))
    cut = write(tmp_path / "cut-scan.jpg", jpeg_with_a_cut_scan(demo))
    truncated = write(tmp_path / "truncated.jpg", cut.read_bytes()[:-2])
    tiff = bytearray(cv2.imencode(".tif", demo)[1].tobytes())
    at = next(pos for pos, tag, _ in tiff_entries(tiff) if tag == 277) + 8  # SamplesPerPixel
    tiff[at:at + 2] = (16003).to_bytes(2, "little" if tiff[:2] == b"II" else "big")
    samples = write(tmp_path / "samples.tif", bytes(tiff))

    for path, needle in ((crc, 'the PNG decoder says "IDAT: CRC error"'),
                         (samples, "cannot decode the image"),
                         (truncated, "JPEG file is truncated")):
        run = cli(path, high, "--no-views", "-q")
        assert run.returncode == 2, (run.returncode, run.stderr)
        assert run.stderr.splitlines() == [run.stderr.strip()], run.stderr  # one line
        assert run.stderr.startswith(f"Error: {path}: ") and needle in run.stderr, run.stderr

    warning = (f'{cut}: the JPEG decoder says "Corrupt JPEG data: premature end of data '
               f'segment"; the image is used as decoded (copy or download the file again if it '
               f'is damaged)')
    quiet = cli(cut, high, "--no-views", "-q", "--json", "-")
    assert quiet.returncode in (0, 1) and quiet.stderr == "", quiet.stderr
    record = json.loads(quiet.stdout)
    image = record["low"] if record["order"] == "given" else record["high"]
    assert image["path"] == str(cut) and image["warning"] == warning
    other = record["high"] if record["order"] == "given" else record["low"]
    assert other["warning"] is None
    said = cli(cut, high, "--no-views").stderr.splitlines()
    assert said[0] == f"Warning: {warning}" and len(said) == 2, said  # then the verdict
    pairs = write(tmp_path / "pairs.csv", f"{cut},{high}\n{crc},{high}\n".encode())
    for jobs in ("1", "2"):  # in this process, and in worker processes
        batch = cli("batch", pairs, "--no-views", "-q", "--jobs", jobs)
        assert batch.returncode == 3 and batch.stderr == "", batch.stderr
        lines = [json.loads(line) for line in batch.stdout.splitlines()]  # as pairs finish
        failed, done = sorted(lines, key=lambda line: "error" not in line)
        assert failed["error"].startswith(f"{crc}: cannot decode the image: the PNG decoder says")
        assert {done["low"]["warning"], done["high"]["warning"]} == {warning, None}


def test_one_minimum_side_for_reading_and_matching(tmp_path, bgr):
    """Reading a file and matching arrays refuse the same sizes (stages.detector.MIN_SIDE_PX)."""
    from scalematch.pipeline import match
    from scalematch.stages.detector import MIN_SIDE_PX

    ok = write(tmp_path / "ok.png", cv2.imencode(".png", bgr[:MIN_SIDE_PX, :60])[1].tobytes())
    assert read_grey(ok).shape == (MIN_SIDE_PX, 60)
    small = write(tmp_path / "small.png",
                  cv2.imencode(".png", bgr[:MIN_SIDE_PX - 1, :60])[1].tobytes())
    with pytest.raises(ImageError, match=f"at least {MIN_SIDE_PX} px"):
        read_grey(small)
    with pytest.raises(ValueError, match=f"at least {MIN_SIDE_PX} px"):
        match(np.zeros((MIN_SIDE_PX - 1, 60), np.float32), np.zeros((100, 100), np.float32))


# --------------------------------------------------------------------------- fuzzing the input path

FORMATS = (".png", ".jpg", ".tif", ".webp", ".bmp")
#: file magic numbers, so random tails reach each format's header parser
MAGIC = (b"\x89PNG\r\n\x1a\n", b"\xff\xd8\xff\xe0", b"II*\x00", b"MM\x00*", b"RIFF\x00\x10\x00\x00WEBP",
         b"BM", b"GIF89a", b"")


def fuzz_cases(bgr: np.ndarray, seed: int = 0):
    """(name, bytes, intact) for random and truncated files of every format, made here.

    Valid files are written by OpenCV and by Pillow (whose TIFF and BMP lay out differently);
    each is cut at two random points; random files start with a format's magic number or not.
    """
    rng = np.random.default_rng(seed)
    small = bgr[:48, :64]
    for ext in FORMATS:
        encoded = {"cv2": cv2.imencode(ext, small)[1].tobytes()}
        buf = __import__("io").BytesIO()
        Image.fromarray(small[:, :, ::-1]).save(buf, format={".jpg": "JPEG", ".tif": "TIFF"}.get(
            ext, ext[1:].upper()))
        encoded["pil"] = buf.getvalue()
        for writer, data in encoded.items():
            if writer == "cv2":
                yield f"intact-{writer}{ext}", data, True
            for cut in sorted(rng.integers(1, len(data), size=2)):
                yield f"cut{cut}-{writer}{ext}", data[:cut], False
    for k, magic in enumerate(MAGIC):
        tail = rng.integers(0, 256, size=int(rng.integers(0, 400)), dtype=np.uint8).tobytes()
        yield f"random{k}.img", magic + tail, False


def test_random_and_truncated_files_give_one_line_errors(tmp_path, bgr):
    """Every broken file: exit 2 with one line 'Error: ...' on stderr, never a traceback."""
    from click.testing import CliRunner

    from scalematch.cli import cli

    good = write(tmp_path / "good.png", cv2.imencode(".png", bgr)[1].tobytes())
    cases = list(fuzz_cases(bgr))
    assert len(cases) >= 30
    for name, data, intact in cases:
        path = write(tmp_path / name, data)
        run = CliRunner().invoke(cli, [str(path), str(good), "--quiet"])
        if intact:
            assert run.exit_code in (0, 1), (name, run.output)
            continue
        lines = run.stderr.strip().splitlines()
        assert run.exit_code == 2 and "Traceback" not in run.output, (name, run.output)
        assert len(lines) == 1 and lines[0].startswith(f"Error: {path}: "), (name, run.stderr)


def test_the_png_header_is_read_as_pillow_reads_it(tmp_path, bgr):
    """PNG files are read without Pillow unless an eXIf chunk comes before the pixels: the
    header must be Pillow's, whatever the layout (grey, colour, alpha, 16-bit, text chunks)."""
    from PIL import PngImagePlugin

    from scalematch.headers import png_header as _png_header

    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    images = {"grey": grey, "bgr": bgr, "bgra": cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA),
              "grey16": grey.astype(np.uint16) * 257}
    for name, img in images.items():
        data = cv2.imencode(".png", img)[1].tobytes()
        assert _png_header(data) is not None, name
        with Image.open(io.BytesIO(data)) as im:
            assert header(data) == (im.size, 1, -1), name
    info = PngImagePlugin.PngInfo()
    info.add_text("Comment", "a text chunk before the pixels")
    path = tmp_path / "text.png"
    Image.fromarray(grey).save(path, pnginfo=info)
    assert _png_header(path.read_bytes()) == ((160, 120), 1, -1)
    exif = Image.Exif()
    exif[0x0112] = 6
    Image.fromarray(grey).save(path, exif=exif.tobytes())
    assert _png_header(path.read_bytes()) == ((160, 120), 6, -1)  # as Pillow reads it
    assert _png_header(png_header_only(12000, 12000)) == ((12000, 12000), 1, -1)
    assert _png_header(b"\x89PNG\r\n\x1a\n" + b"\x00" * 40) is None  # no IHDR


def test_a_decode_out_of_memory_is_a_memory_error_not_a_corrupt_file(tmp_path, monkeypatch):
    """With no memory left to decode (OpenCV then returns no image, or raises "Insufficient
    memory"), read_image raises MemoryError (an internal error: exit 4, batch error_kind
    internal), not ImageError "truncated or corrupt" (exit 2), which would blame a good file.
    Seen in a batch under RLIMIT_AS: a 4000x2250 JPEG that another worker decoded was called
    corrupt."""
    import subprocess
    import sys

    big = tmp_path / "big.png"
    cv2.imwrite(str(big), np.zeros((4000, 6000, 3), np.uint8))  # 72 MB decoded, 200 kB stored
    # the limit set once the modules are in: 40 MB more than the process holds, too little
    code = ("import resource, sys\n"
            "from scalematch.imageio import read_image\n"
            "vm = int(open('/proc/self/statm').read().split()[0]) * resource.getpagesize()\n"
            "resource.setrlimit(resource.RLIMIT_AS, (vm + (40 << 20), vm + (40 << 20)))\n"
            "try:\n"
            "    read_image(sys.argv[1])\n"
            "except MemoryError as exc:\n"
            "    print('MemoryError', exc)\n")
    done = subprocess.run([sys.executable, "-c", code, str(big)], capture_output=True,
                          text=True, timeout=60)
    assert done.stdout.startswith(f"MemoryError {big}: no memory to decode"), (done.stdout,
                                                                              done.stderr)
    # OpenCV's own words for it
    def insufficient(*args):
        raise cv2.error("OpenCV(5.0.0) alloc.cpp:73: error: (-4:Insufficient memory) Failed to "
                        "allocate 72000000 bytes in function 'OutOfMemoryError'")

    monkeypatch.setattr(cv2, "imdecode", insufficient)
    with pytest.raises(MemoryError, match="no memory to decode"):
        read_image(big)


#: a JPEG decoded at half size against the full decode shrunk by INTER_AREA, grey levels rms
#: (measured 0.35 on a 16 MP photo; 8-bit rounding of the decoder's output alone is 0.29)
REDUCED_RMS = 1.0
#: the shift between the two, px of the reduced image (measured under 0.001)
REDUCED_SHIFT_PX = 0.05


def test_a_large_jpeg_is_decoded_reduced_as_if_shrunk():
    """data/raccoon.jpg (1024x768) with a working size of 400 px: decoded at half size (512 px
    >= 400, 256 px would be below), the pixels of the full decode shrunk by 2 (INTER_AREA, the
    centre-aligned map the answer is mapped back with), not shifted."""
    path = ROOT / "data" / "raccoon.jpg"
    d = read_reduced(path, at_least=400)
    assert d.factor == 2 and d.size == (1024, 768) and d.image.shape[:2] == (384, 512)
    full = to_grey(read_image(path))
    ref = cv2.resize(full, (512, 384), interpolation=cv2.INTER_AREA)
    half = to_grey(d.image)
    assert np.sqrt(np.mean((half - ref) ** 2)) < REDUCED_RMS
    shift, _ = cv2.phaseCorrelate(ref.astype(np.float64), half.astype(np.float64))
    assert np.hypot(*shift) < REDUCED_SHIFT_PX
    # not above the working size: as read_image reads it
    for at_least in (600, None):
        same = read_reduced(path, at_least=at_least)
        assert same.factor == 1 and same.size == (1024, 768)
        np.testing.assert_array_equal(same.image, read_image(path))


def test_only_jpeg_is_decoded_reduced_and_orientation_is_kept(tmp_path, bgr):
    """A PNG is decoded in full whatever its size; a JPEG stored sideways (EXIF 6) is turned
    upright at its reduced size too, and its size is the upright one."""
    png = write(tmp_path / "a.png", cv2.imencode(".png", bgr)[1].tobytes())
    d = read_reduced(png, at_least=40)
    assert d.factor == 1 and d.image.shape == bgr.shape
    plain = read_reduced(write(tmp_path / "p.jpg", jpeg_bytes(bgr)), at_least=60)
    turned = read_reduced(write(tmp_path / "r.jpg", jpeg_bytes(bgr, 6)), at_least=60)
    assert plain.factor == turned.factor == 2  # 160 px: 80 >= 60, 40 would be below
    assert plain.size == (160, 120) and turned.size == (120, 160)
    assert turned.image.shape[:2] == (80, 60)
    np.testing.assert_array_equal(turned.image, np.rot90(plain.image, k=-1))


def test_an_mpo_file_is_decoded_reduced_as_a_jpeg(tmp_path, bgr):
    """MPO (drone and some camera photos: JPEG images in a row) is a JPEG to OpenCV, which
    decodes the first image: at a reduced size too."""
    first = Image.fromarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
    data = io.BytesIO()
    first.save(data, "MPO", save_all=True, append_images=[first.transpose(Image.FLIP_LEFT_RIGHT)])
    path = write(tmp_path / "drone.jpg", data.getvalue())
    assert header(data.getvalue()).scan >= 0
    d = read_reduced(path, at_least=60)
    assert d.factor == 2 and d.size == (160, 120) and d.image.shape[:2] == (60, 80)
    full = to_grey(read_image(path))
    ref = cv2.resize(full, (80, 60), interpolation=cv2.INTER_AREA)
    assert np.sqrt(np.mean((to_grey(d.image) - ref) ** 2)) < REDUCED_RMS  # measured 0.35


# --------------------------------------------------------------------------- the seeded corpus

@pytest.fixture(scope="module")
def corpus_dir(tmp_path_factory) -> Path:
    """The fuzz corpus of ``scalematch.lab.fuzz`` (250 files, seed 0), written once."""
    from scalematch.lab.fuzz import write_corpus

    folder = tmp_path_factory.mktemp("corpus")
    write_corpus(folder, seed=0)
    return folder


def test_every_file_of_the_fuzz_corpus_is_read_or_refused_in_one_line(corpus_dir):
    """The demo image in five formats with byte flips, header flips, truncation, repeated
    chunks and huge size fields: each file is decoded or refused with one line naming it,
    never another exception. (scripts/fuzz_inputs.py measures the time and memory of each.)"""
    from scalematch.working import read_pair
    from scalematch import Config

    outcomes = {"read": 0, "refused": 0}
    paths = sorted(corpus_dir.iterdir())
    assert len(paths) == 250
    for path in paths:
        try:
            read_pair(path, path, Config())
            outcomes["read"] += 1
        except ImageError as exc:
            assert str(exc).startswith(f"{path}: ") and "\n" not in str(exc), path.name
            outcomes["refused"] += 1
    assert outcomes["read"] > 20 and outcomes["refused"] > 100, outcomes


def test_the_fuzz_corpus_through_the_command_line_exits_0_1_or_2(corpus_dir, capfd):
    """Every file of the corpus as LOW against the demo's finer image: 0 or 1 for a file that
    decodes, with nothing on stderr under -q (a damaged JPEG's warning is in the JSON), 2
    with one "Error:" line for one that does not; never 4 (an internal error). Nothing of the
    decoders' own (libpng, libjpeg, libtiff) reaches the process's stderr."""
    from click.testing import CliRunner

    from scalematch.cli import cli

    high = ROOT / "data" / "demo_high.png"
    codes = {}
    for path in sorted(corpus_dir.iterdir()):
        run = CliRunner().invoke(cli, [str(path), str(high), "--no-views", "-q"])
        codes[run.exit_code] = codes.get(run.exit_code, 0) + 1
        assert run.exit_code in (0, 1, 2), (path.name, run.exit_code, run.output)
        if run.exit_code == 2:
            lines = run.stderr.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith(f"Error: {path}: "), run.stderr
        else:
            assert run.stderr == "", (path.name, run.stderr)
    assert codes.get(2, 0) > 100 and codes.get(0, 0) + codes.get(1, 0) > 20, codes
    assert capfd.readouterr().err == ""
