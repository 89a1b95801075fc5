"""Synthetic zoom pairs with exact ground truth (EVALUATION.md, "Synthetic zoom pairs").

``zoom_warp`` is the camera model: blur by 0.5*sqrt(r^2 - 1), rotate by theta and shrink by r in
one affine warp onto a canvas that holds the whole rotated image. Everything else that cuts
pairs (crops, grey-level change, noise, window cut) builds on it.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterable, Iterator, List, Optional, Sequence, Tuple, Union

import cv2
import numpy as np

from ..geometry import apply, compose, invert, similarity_matrix

#: The camera model of EVALUATION.md: a coarser image is blurred by 0.5 sqrt(r^2 - 1) before it
#: is shrunk by r, "so that after shrinking the camera blur is about 0.5 px" (the matcher
#: assumes the same: HarrisParams.camera_blur_px, PixelParams.camera_blur_px)
CAMERA_BLUR_PX = 0.5


def zoom_warp(image: np.ndarray, ratio: float, angle_deg: float,
              interpolation: int = cv2.INTER_LINEAR) -> Tuple[np.ndarray, np.ndarray]:
    """Blur, rotate by ``angle_deg`` and shrink by ``ratio`` with one warp; return (image, A).

    The output canvas holds the whole rotated, shrunk image; ``A`` (2x3) maps a pixel of
    ``image`` to its pixel in the output (OpenCV convention, pixel centres at integers).
    """
    img = np.asarray(image)
    blur = CAMERA_BLUR_PX * math.sqrt(max(ratio * ratio - 1.0, 0.0))
    if blur > 0.05:
        img = cv2.GaussianBlur(img, (0, 0), blur, borderType=cv2.BORDER_REFLECT_101)
    h, w = img.shape[:2]
    lin = similarity_matrix(1.0 / ratio, angle_deg)
    corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], dtype=np.float64)
    mapped = apply(lin, corners)
    lo = mapped.min(axis=0)
    hi = mapped.max(axis=0)
    size = np.ceil(hi - lo).astype(int) + 1
    a = lin.copy()
    a[:, 2] = -lo
    out = cv2.warpAffine(img, a, (int(size[0]), int(size[1])), flags=interpolation,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return out, a


# --------------------------------------------------------------------------------------------
# Zoom pairs cut from a real photo (EVALUATION.md steps 1-3)
# --------------------------------------------------------------------------------------------

#: Size (width, height) of the high-resolution crop, px (EVALUATION.md step 1: "about 640x480").
HIGH_SIZE = (640, 480)
#: (width, height) of the high crop at ratios beyond 10 (at ratios 12 and 16 a 960x720 crop
#: has a footprint of 60 to 80 low pixels): a 640x480 crop at ratio 16 covers 40x30 low px
HIGH_SIZE_BEYOND_10 = (960, 720)
#: Largest low-resolution image (width, height), px (EVALUATION.md step 2: a finite sensor).
LOW_MAX = (1024, 768)
#: Candidate crop positions; the most textured is kept (EVALUATION.md step 1).
N_CROP_CANDIDATES = 6
#: Margin kept between a crop and the photo border, as a fraction of the photo side
#: ("away from the border": avoids lens vignetting and the rotated canvas' black corners).
BORDER_MARGIN_FRAC = 0.05
#: Grey-level gain range (EVALUATION.md step 2).
GAIN_RANGE = (0.75, 1.2)
#: Grey-level offset range, grey levels (EVALUATION.md step 2).
OFFSET_RANGE = (-15.0, 15.0)
#: Range of the std of the additive Gaussian noise, grey levels (EVALUATION.md step 2: "up to 3").
NOISE_STD_RANGE = (0.0, 3.0)
#: Rotation range, degrees, [lo, hi) (EVALUATION.md step 2).
ANGLE_RANGE = (-180.0, 180.0)


@dataclass(frozen=True, eq=False)
class ZoomPair:
    """A low/high pair with its ground truth (or none, for an unrelated pair).

    ``truth`` maps a ``high`` pixel to a ``low`` pixel (OpenCV pixel centres at integers): a 2x3
    similarity for synthetic pairs, a 3x3 homography for real pairs such as boat, None when the
    two images show different scenes. Grey levels are float32 in the 8-bit range.
    """

    low: np.ndarray = field(repr=False)  #: (H, W) float32, the low-resolution image
    high: np.ndarray = field(repr=False)  #: (h, w) float32, the high-resolution image
    truth: Optional[np.ndarray] = field(repr=False)  #: 2x3 or 3x3 float64, high px -> low px
    ratio: float  #: resolution ratio r (high px per low px); nan when unknown
    angle_deg: float  #: rotation of low relative to high, degrees; nan when unknown
    gain: float = 1.0  #: grey-level gain applied to low
    offset: float = 0.0  #: grey-level offset applied to low
    noise_std: float = 0.0  #: std of the Gaussian noise added to low, grey levels
    source: str = ""  #: where low comes from (photo name, "boat 1->3", ...)
    crop_xy: Tuple[int, int] = (0, 0)  #: top-left of ``high`` in its photo, px
    window_xy: Tuple[int, int] = (0, 0)  #: top-left of ``low`` in the warped canvas, px
    high_source: str = ""  #: where high comes from ("" = same as ``source``)
    tilt: float = 1.0  #: tilt of the low view (1: a plain zoom pair)
    longitude_deg: float = 0.0  #: direction of the tilt, degrees


def _translation(tx: float, ty: float) -> np.ndarray:
    return np.array([[1.0, 0.0, tx], [0.0, 1.0, ty]])


def crop_size(photo_shape: Tuple[int, int], high_size: Tuple[int, int] = HIGH_SIZE) -> Tuple[int, int]:
    """(w, h) of the high crop: ``high_size`` but at most half of the photo on each side."""
    ph, pw = photo_shape[:2]
    return min(int(high_size[0]), pw // 2), min(int(high_size[1]), ph // 2)


def texture_score(crop: np.ndarray, ratio: float) -> float:
    """Mean gradient magnitude (grey levels/px) of ``crop`` (h, w) once shrunk by ``ratio``.

    What the low image will see of the crop (EVALUATION.md step 1): the crop is reduced with
    ``cv2.INTER_AREA`` and differentiated with 3x3 Sobel kernels (divided by 8 to be per pixel).
    """
    w = max(int(round(crop.shape[1] / ratio)), 3)
    h = max(int(round(crop.shape[0] / ratio)), 3)
    small = cv2.resize(np.asarray(crop, np.float32), (w, h), interpolation=cv2.INTER_AREA)
    gx = cv2.Sobel(small, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(small, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    return float(np.mean(np.sqrt(gx * gx + gy * gy)))


#: Which of the candidate crops a pair takes: EVALUATION.md's "most" textured, or the "least"
#: (the hard set, docs/results/HARDSET.md: a crop of plain sky or a smooth wall is what starves the
#: detector)
CROP_PICKS = ("most", "least")


def choose_crop(photo: np.ndarray, ratio: float, rng: np.random.Generator,
                high_size: Tuple[int, int] = HIGH_SIZE,
                n_candidates: int = N_CROP_CANDIDATES,
                pick: str = "most") -> Tuple[int, int, int, int]:
    """(x, y, w, h) of the most (``pick="least"``: the least) textured of ``n_candidates``
    random crops away from the border.

    Parameters
    ----------
    photo : (H, W) array
    ratio : float
        The zoom ratio; texture is measured on the crop shrunk by it (``texture_score``).
    rng : numpy Generator
        Draws the ``n_candidates`` positions (2 integers each).
    """
    ph, pw = photo.shape[:2]
    w, h = crop_size(photo.shape, high_size)
    if w < 16 or h < 16:
        raise ValueError(f"photo {pw}x{ph} is too small to cut a high-resolution crop from")
    mx = min(int(BORDER_MARGIN_FRAC * pw), (pw - w) // 2)
    my = min(int(BORDER_MARGIN_FRAC * ph), (ph - h) // 2)
    return most_textured_crop(photo, (w, h), (mx, my), n_candidates, ratio, rng, pick)


def most_textured_crop(photo: np.ndarray, size: Tuple[int, int], margin: Tuple[int, int],
                       n_candidates: int, ratio: float, rng: np.random.Generator,
                       pick: str = "most") -> Tuple[int, int, int, int]:
    """(x, y, w, h): the most textured (``texture_score``) of ``n_candidates`` random crops
    (``pick="least"``: the least textured; the same candidates either way).

    Each candidate draws x in [mx, W - w - mx], then y in [my, H - h - my] (``margin`` = (mx,
    my)); the first of equally textured crops wins.
    """
    if pick not in CROP_PICKS:
        raise ValueError(f"pick must be one of {CROP_PICKS}, got {pick!r}")
    ph, pw = photo.shape[:2]
    (w, h), (mx, my) = size, margin
    sign = 1.0 if pick == "most" else -1.0
    best, best_score = None, -math.inf
    for _ in range(max(n_candidates, 1)):
        x = int(rng.integers(mx, pw - w - mx + 1))
        y = int(rng.integers(my, ph - h - my + 1))
        score = sign * texture_score(photo[y:y + h, x:x + w], ratio)
        if score > best_score:
            best, best_score = (x, y, w, h), score
    return best


def window_offset(canvas_wh: Tuple[int, int], footprint: np.ndarray, low_max: Tuple[int, int],
                  rng: np.random.Generator) -> Tuple[int, int, int, int]:
    """(x, y, w, h) of a window at most ``low_max`` of the canvas holding the whole footprint.

    Parameters
    ----------
    canvas_wh : (int, int)
        Canvas width and height, px.
    footprint : (N, 2) array
        Points (x, y) that must lie inside the window (the high image's corners in the canvas).
    low_max : (int, int)
        Largest window (width, height); a canvas that fits is kept whole.
    rng : numpy Generator
        Draws the offset uniformly among the windows that hold the footprint (2 integers).
    """
    cw, ch = int(canvas_wh[0]), int(canvas_wh[1])
    ww, wh = min(cw, int(low_max[0])), min(ch, int(low_max[1]))
    lo = np.floor(footprint.min(axis=0)).astype(int)
    hi = np.ceil(footprint.max(axis=0)).astype(int)
    out = []
    for lo_k, hi_k, win, canvas in ((lo[0], hi[0], ww, cw), (lo[1], hi[1], wh, ch)):
        first = max(0, hi_k - win + 1)
        last = min(lo_k, canvas - win)
        if first > last:
            raise ValueError(f"the high image's footprint ({hi_k - lo_k + 1} px) does not fit in "
                             f"a {win} px window; use a larger ratio or a smaller high_size")
        out.append(int(rng.integers(first, last + 1)))
    return out[0], out[1], ww, wh


def grey_change(rng: np.random.Generator) -> Tuple[float, float, float]:
    """(gain, offset, noise std) of a low image's grey-level change (EVALUATION.md step 2),
    drawn in that order from ``GAIN_RANGE``, ``OFFSET_RANGE`` and ``NOISE_STD_RANGE``."""
    return (float(rng.uniform(*GAIN_RANGE)), float(rng.uniform(*OFFSET_RANGE)),
            float(rng.uniform(*NOISE_STD_RANGE)))


def degrade(image: np.ndarray, gain: float, offset: float, noise_std: float,
            rng: np.random.Generator) -> np.ndarray:
    """gain * image + offset + N(0, noise_std^2), rounded and clipped to 0..255, float32."""
    out = image.astype(np.float32) * np.float32(gain) + np.float32(offset)
    if noise_std > 0:
        out += rng.normal(0.0, noise_std, size=out.shape).astype(np.float32)
    return np.clip(np.rint(out), 0, 255).astype(np.float32)


def cut_low(canvas: np.ndarray, to_canvas: np.ndarray, high_wh: Tuple[int, int],
            low_max: Tuple[int, int], gain: float, offset: float, noise_std: float,
            rng: np.random.Generator) -> Tuple[np.ndarray, np.ndarray, Tuple[int, int]]:
    """(low, truth 2x3 high px -> low px, window top-left): the window of at most ``low_max``
    of ``canvas`` that holds the high image's footprint (``window_offset``), changed in grey
    level and noise (``degrade``); ``to_canvas`` maps a high px to the canvas. ``rng`` draws
    the window offset, then the noise."""
    w, h = high_wh
    corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], dtype=np.float64)
    wx, wy, ww, wh = window_offset((canvas.shape[1], canvas.shape[0]), apply(to_canvas, corners),
                                   low_max, rng)
    low = degrade(canvas[wy:wy + wh, wx:wx + ww], gain, offset, noise_std, rng)
    return low, compose(_translation(-wx, -wy), to_canvas), (wx, wy)


def zoom_pair_from_crop(photo: np.ndarray, crop: Tuple[int, int, int, int], ratio: float,
                        rng: np.random.Generator, low_max: Tuple[int, int] = LOW_MAX,
                        source: str = "") -> ZoomPair:
    """A zoom pair whose high image is the crop ``(x, y, w, h)`` of ``photo`` (steps 2-3).

    ``low`` is the whole photo blurred, rotated by a random angle and shrunk by ``ratio``
    (``zoom_warp``), cut to a window of at most ``low_max`` holding the crop's footprint
    (``window_offset``), then changed in grey level and noise (``degrade``; doing the cut first
    only saves work). The truth is ``T(-window) o A_warp o T(crop)``. ``rng`` draws, in order:
    the angle, gain, offset, noise std, window offset and the noise.
    """
    photo = np.asarray(photo, dtype=np.float32)
    if photo.ndim != 2:
        raise ValueError(f"photo must be a grey (H, W) array, got shape {photo.shape}")
    if not ratio >= 1.0:
        raise ValueError(f"ratio must be >= 1, got {ratio}")
    x, y, w, h = (int(v) for v in crop)
    high = np.ascontiguousarray(photo[y:y + h, x:x + w])
    angle = float(rng.uniform(*ANGLE_RANGE))
    gain, offset, noise_std = grey_change(rng)
    canvas, warp = zoom_warp(photo, ratio, angle)
    low, truth, window = cut_low(canvas, compose(warp, _translation(x, y)), (w, h), low_max,
                                 gain, offset, noise_std, rng)
    return ZoomPair(low=low, high=high, truth=truth, ratio=float(ratio), angle_deg=angle,
                    gain=gain, offset=offset, noise_std=noise_std, source=source,
                    crop_xy=(x, y), window_xy=window)


def make_zoom_pair(photo: np.ndarray, ratio: float, rng: np.random.Generator,
                   high_size: Tuple[int, int] = HIGH_SIZE, low_max: Tuple[int, int] = LOW_MAX,
                   source: str = "", pick: str = "most") -> ZoomPair:
    """Cut a synthetic zoom pair with exact ground truth from one photo (EVALUATION.md 1-3).

    ``high`` is the most textured of 6 random crops (``choose_crop``); ``low`` is the whole photo
    blurred, rotated by a random angle and shrunk by ``ratio``, cut to at most ``low_max`` around
    the high image's footprint, with a grey-level change and noise (``zoom_pair_from_crop``).

    Parameters
    ----------
    photo : (H, W) float32 array
        Grey levels in the 8-bit range.
    ratio : float
        Resolution ratio r >= 1 (high px per low px).
    rng : numpy Generator
        All randomness: crop positions, angle, gain, offset, noise std, window, noise.
    high_size, low_max : (int, int)
        (width, height) of the high crop and the largest low image, px.
    source : str
        A name recorded in the pair (e.g. the photo file name).

    Returns
    -------
    ZoomPair
        ``truth`` is a 2x3 float64 similarity, high px -> low px.
    """
    photo = np.asarray(photo, dtype=np.float32)
    if photo.ndim != 2:
        raise ValueError(f"photo must be a grey (H, W) array, got shape {photo.shape}")
    if not ratio >= 1.0:
        raise ValueError(f"ratio must be >= 1, got {ratio}")
    crop = choose_crop(photo, ratio, rng, high_size, pick=pick)
    return zoom_pair_from_crop(photo, crop, ratio, rng, low_max, source)


def make_unrelated_pair(photo_low: np.ndarray, photo_high: np.ndarray, ratio: float,
                        rng: np.random.Generator, high_size: Tuple[int, int] = HIGH_SIZE,
                        low_max: Tuple[int, int] = LOW_MAX, source_low: str = "",
                        source_high: str = "") -> ZoomPair:
    """The low image of ``photo_low`` against a high crop of ``photo_high`` (truth None).

    Both are made exactly as in ``make_zoom_pair`` (the high crop is the most textured of 6);
    use two photos of different scenes, so that any match claimed is false.
    """
    low_pair = make_zoom_pair(photo_low, ratio, rng, high_size, low_max, source_low)
    x, y, w, h = choose_crop(np.asarray(photo_high, np.float32), ratio, rng, high_size)
    high = np.ascontiguousarray(np.asarray(photo_high, np.float32)[y:y + h, x:x + w])
    return replace(low_pair, high=high, truth=None, crop_xy=(x, y),
                   high_source=source_high or "other photo")


def unrelated_indices(sources: Sequence[str], ratios: Sequence[float], count: int,
                      rng: np.random.Generator, scene_of: Callable[[str], str]) -> List[Tuple[int, int]]:
    """``count`` index pairs (i, j): low of pair i against high of pair j, never one scene.

    Only pairs of the same ratio are combined, and only when ``scene_of(source)`` differs (two
    photos of one scene could truly match). Combinations are drawn without replacement (one
    permutation by ``rng``); fewer than ``count`` come back when there are not enough.
    """
    scenes = [scene_of(s) for s in sources]
    combos = [(i, j) for i in range(len(sources)) for j in range(len(sources))
              if ratios[i] == ratios[j] and scenes[i] != scenes[j]]
    order = rng.permutation(len(combos))[:max(int(count), 0)]
    return [combos[k] for k in order]


def unrelated_from_pairs(pairs: Sequence[ZoomPair], count: int, rng: np.random.Generator,
                         scene_of: Callable[[str], str]) -> List[ZoomPair]:
    """Recombine zoom pairs into ``count`` unrelated pairs: low of one, high of another scene.

    Parameters
    ----------
    pairs : sequence of ZoomPair
        Pairs with a ``source`` each (e.g. from ``pairs_from_photos``).
    count : int
    rng : numpy Generator
        Draws the combinations (``unrelated_indices``).
    scene_of : callable
        ``source`` -> scene name, e.g. ``datasets.scene_of``.

    Returns
    -------
    list of ZoomPair
        ``truth`` None, ``high_source`` naming where the high image comes from.
    """
    idx = unrelated_indices([p.source for p in pairs], [p.ratio for p in pairs], count, rng,
                            scene_of)
    return [replace(pairs[i], high=pairs[j].high, truth=None, crop_xy=pairs[j].crop_xy,
                    high_source=pairs[j].source) for i, j in idx]


def pair_rng(seed: int, source: str, ratio: float) -> np.random.Generator:
    """The generator of one pair: from ``seed``, the source name and the ratio only.

    A pair therefore does not depend on which other photos or ratios are in the run: a run on
    the first 10 photos makes the same pairs as the full run does for them.
    """
    key = zlib.crc32(source.encode("utf-8"))
    return np.random.default_rng([int(seed), key, int(round(float(ratio) * 1000))])


def high_size_for(ratio: float) -> Tuple[int, int]:
    """The high crop's size at ``ratio``: ``HIGH_SIZE``, and ``HIGH_SIZE_BEYOND_10`` past 10.

    >>> high_size_for(10), high_size_for(16)
    ((640, 480), (960, 720))
    """
    return HIGH_SIZE if ratio <= 10 else HIGH_SIZE_BEYOND_10


def pairs_from_photos(paths: Iterable[Union[str, Path]], ratios: Sequence[float], seed: int = 0,
                      high_size: Optional[Tuple[int, int]] = None,
                      low_max: Tuple[int, int] = LOW_MAX, pick: str = "most") -> Iterator[ZoomPair]:
    """Zoom pairs from photo files: for each path in the order given, each ratio in order.

    Each photo is read once (grey float32, EXIF orientation applied, ``imageio.read_grey``), and
    each pair is made by ``make_zoom_pair`` with the generator ``pair_rng(seed, file name,
    ratio)``, so the output is deterministic given ``seed`` and independent of the other
    paths and ratios. ``source`` is the file name.

    Yields
    ------
    ZoomPair
    """
    from ..imageio import read_grey  # light import, kept local so this module stays pure numpy

    ratios = [float(r) for r in ratios]
    for path in paths:
        p = Path(path)
        photo = read_grey(p)
        for r in ratios:
            yield make_zoom_pair(photo, r, pair_rng(seed, p.name, r),
                                 high_size or high_size_for(r), low_max, source=p.name, pick=pick)


# --------------------------------------------------------------------------------------------
# Tilted zoom pairs (docs/EVALUATION-TILT.md): zoom x rotation x tilt, exact truth
# --------------------------------------------------------------------------------------------

#: Tilts of the tilted zoom pairs (Morel & Yu 2009 sample t = sqrt(2)^k; 4 is a view 75.5 deg
#: off the normal)
TILTS = (1.41, 2.0, 2.83, 4.0)
#: Longitude range of the tilt, degrees, [lo, hi)
LONGITUDE_RANGE = (0.0, 180.0)


def tilted_linear(ratio: float, angle_deg: float, tilt: float, longitude_deg: float) -> np.ndarray:
    """2x2 ``(1/r) R(theta) R(phi)^T diag(1/t, 1) R(phi)``: compress by t along phi, then zoom
    out by r and turn by theta (every affine map with positive determinant has this form)."""
    rot = similarity_matrix(1.0, angle_deg)[:, :2]
    turn = similarity_matrix(1.0, longitude_deg)[:, :2]
    return (1.0 / ratio) * rot @ turn.T @ np.diag([1.0 / tilt, 1.0]) @ turn


def affine_warp(image: np.ndarray, linear: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Warp ``image`` by the 2x2 shrinking map ``linear`` with anti-aliasing; (canvas, A 2x3).

    ``linear = U diag(s1, s2) V^T`` (SVD): the image is turned by V^T onto a canvas, blurred by
    ``CAMERA_BLUR_PX * sqrt(1/s_k^2 - 1)`` along each axis (the camera model of ``zoom_warp``,
    per direction), then mapped by ``U diag(s1, s2)``. ``A`` maps an ``image`` pixel to the
    output pixel (OpenCV convention); the output canvas holds the whole warped image.
    """
    img = np.asarray(image, np.float32)
    u, sv, vt = np.linalg.svd(np.asarray(linear, np.float64))
    if np.linalg.det(vt) < 0:  # keep both factors rotations (linear has det > 0)
        vt[1] *= -1.0
        u[:, 1] *= -1.0
    h, w = img.shape[:2]
    corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], dtype=np.float64)

    def _onto_canvas(lin: np.ndarray, pts: np.ndarray) -> Tuple[np.ndarray, Tuple[int, int]]:
        m = np.hstack([lin, np.zeros((2, 1))])
        mapped = apply(m, pts)
        m[:, 2] = -mapped.min(axis=0)
        size = np.ceil(mapped.max(axis=0) - mapped.min(axis=0)).astype(int) + 1
        return m, (int(size[0]), int(size[1]))

    turn, size1 = _onto_canvas(vt, corners)
    turned = cv2.warpAffine(img, turn, size1, flags=cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    sx, sy = (CAMERA_BLUR_PX * math.sqrt(max(1.0 / (v * v) - 1.0, 0.0)) for v in sv)
    turned = cv2.GaussianBlur(turned, (0, 0), sigmaX=max(sx, 0.01), sigmaY=max(sy, 0.01))
    shrink, size2 = _onto_canvas(u @ np.diag(sv), apply(turn, corners))
    out = cv2.warpAffine(turned, shrink, size2, flags=cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return out, compose(shrink, turn)


def make_tilted_pair(photo: np.ndarray, ratio: float, tilt: float, rng: np.random.Generator,
                     high_size: Tuple[int, int] = HIGH_SIZE, low_max: Tuple[int, int] = LOW_MAX,
                     source: str = "") -> ZoomPair:
    """A zoom pair whose low image also sees the scene obliquely (docs/EVALUATION-TILT.md).

    As ``make_zoom_pair`` (most textured of 6 crops, measured at the mean shrink
    ``ratio * sqrt(tilt)``; grey-level change, noise, a window of at most ``low_max``), but the
    photo is warped by ``tilted_linear(ratio, theta, tilt, phi)`` with theta uniform in
    [-180, 180) and phi in [0, 180). The directional ratios are ``ratio`` and ``ratio * tilt``.
    ``truth`` is the exact 2x3 affine map high px -> low px. ``rng`` draws, in order: the crop
    positions, theta, phi, gain, offset, noise std, the window offset and the noise.
    """
    photo = np.asarray(photo, dtype=np.float32)
    if not (ratio >= 1.0 and tilt >= 1.0):
        raise ValueError(f"ratio and tilt must be >= 1, got {ratio}, {tilt}")
    x, y, w, h = choose_crop(photo, ratio * math.sqrt(tilt), rng, high_size)
    high = np.ascontiguousarray(photo[y:y + h, x:x + w])
    angle = float(rng.uniform(*ANGLE_RANGE))
    longitude = float(rng.uniform(*LONGITUDE_RANGE))
    gain, offset, noise_std = grey_change(rng)
    canvas, warp = affine_warp(photo, tilted_linear(ratio, angle, tilt, longitude))
    low, truth, window = cut_low(canvas, compose(warp, _translation(x, y)), (w, h), low_max,
                                 gain, offset, noise_std, rng)
    return ZoomPair(low=low, high=high, truth=truth, ratio=float(ratio), angle_deg=angle,
                    gain=gain, offset=offset, noise_std=noise_std, source=source,
                    crop_xy=(x, y), window_xy=window, tilt=float(tilt), longitude_deg=longitude)


# --------------------------------------------------------------------------------------------
# Oblique finer pairs: the finer image is the one seen obliquely (docs/design/VIEWS.md)
# --------------------------------------------------------------------------------------------

#: (width, height) of the high crop of an oblique pair, at most: its footprint in the low image
#: is stretched by tilt / ratio along one axis and must fit the low image's 1024x768
#: (EVALUATION.md step 2) at any rotation (``oblique_high_size``)
OBLIQUE_HIGH_SIZE = (400, 300)
#: Longest footprint of an oblique pair's crop in the low image, px: within the 768 px side of
#: ``LOW_MAX`` with room for the window's rounding
OBLIQUE_MAX_FOOTPRINT_PX = 740.0
#: (ratio, tilt) of the oblique sets: directional ratios r and r / t, the smaller one 0.5 or
#: 0.71 (a telephoto seen obliquely against a frontal wide shot: coarser than the wide shot
#: along one axis)
OBLIQUE_CASES = ((2.0, 2.83), (2.0, 4.0), (4.0, 5.66), (4.0, 8.0))
#: Random crops of the oblique view tried, at most, to find ``N_CROP_CANDIDATES`` that lie
#: wholly on the photo (the view's canvas has empty corners)
OBLIQUE_CROP_TRIES = 400
#: ... and where none does, the crop is made 0.8x smaller, at most this many times (a steep
#: view of a wide photo across its short side is narrow: 281 px for 2250 px at tilt 8)
OBLIQUE_CROP_SHRINKS = 3
#: ... down to this side, px: twice the descriptor's 16 px window
OBLIQUE_MIN_CROP_PX = 32


def oblique_high_size(ratio: float, tilt: float) -> Tuple[int, int]:
    """(w, h) of an oblique pair's crop: ``OBLIQUE_HIGH_SIZE``, shrunk so that its diagonal
    stretched by ``tilt / ratio`` (the longest its footprint can be, at any rotation) stays
    within ``OBLIQUE_MAX_FOOTPRINT_PX``.

    >>> oblique_high_size(2.0, 2.83), oblique_high_size(2.0, 4.0)
    ((400, 300), (296, 222))
    """
    w, h = OBLIQUE_HIGH_SIZE
    k = min(1.0, OBLIQUE_MAX_FOOTPRINT_PX / (math.hypot(w, h) * max(tilt / ratio, 1.0)))
    return int(w * k), int(h * k)


def _crop_on_photo(view: np.ndarray, back: np.ndarray, photo_wh: Tuple[int, int],
                   size: Tuple[int, int], shrink: float,
                   rng: np.random.Generator) -> Optional[Tuple[int, int]]:
    """(x, y) of the most textured (``texture_score`` at ``shrink``) of ``N_CROP_CANDIDATES``
    random crops of ``size`` of ``view`` whose corners ``back`` maps onto the photo, away from
    its border; None when ``OBLIQUE_CROP_TRIES`` draws find none."""
    (pw, ph), (w, h) = photo_wh, size
    corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], dtype=np.float64)
    mx, my = int(BORDER_MARGIN_FRAC * pw), int(BORDER_MARGIN_FRAC * ph)
    best, best_score, found = None, -math.inf, 0
    for _ in range(OBLIQUE_CROP_TRIES):
        x = int(rng.integers(0, view.shape[1] - w + 1))
        y = int(rng.integers(0, view.shape[0] - h + 1))
        on_photo = apply(back, corners + [x, y])
        if (on_photo[:, 0].min() < mx or on_photo[:, 0].max() > pw - 1 - mx
                or on_photo[:, 1].min() < my or on_photo[:, 1].max() > ph - 1 - my):
            continue
        score = texture_score(view[y:y + h, x:x + w], shrink)
        if score > best_score:
            best, best_score = (x, y), score
        found += 1
        if found == N_CROP_CANDIDATES:
            break
    return best


def make_oblique_pair(photo: np.ndarray, ratio: float, tilt: float, rng: np.random.Generator,
                      high_size: Optional[Tuple[int, int]] = None,
                      low_max: Tuple[int, int] = LOW_MAX, source: str = "") -> ZoomPair:
    """A zoom pair whose *finer* image sees the scene obliquely and the coarser one frontally.

    The high image is a crop of the photo turned by a random longitude phi and compressed by
    ``tilt`` along x (``affine_warp`` of ``tilted_linear(1, phi, tilt, phi)``, blurred along that
    axis as a camera would); the low image is the whole photo zoomed out by ``ratio`` and turned by theta, as in
    ``make_zoom_pair`` (grey-level change, noise, a window of at most ``low_max``). The
    directional ratios (high px per low px) are ``ratio`` and ``ratio / tilt``: below 1 the
    finer image is coarser than the other along one axis, which only a view of the coarser image
    undoes. The crop is the most textured (measured at the mean shrink ``ratio / sqrt(tilt)``) of
    6 random crops lying wholly on the photo, of ``high_size`` (None: ``oblique_high_size``;
    0.8x smaller, up to ``OBLIQUE_CROP_SHRINKS`` times, where the view holds none).
    ``truth`` is the exact 2x3 affine map high px -> low px. ``rng`` draws, in order: phi, the crop positions, theta, gain, offset, noise std, the
    window offset and the noise.

    >>> img = np.random.default_rng(0).uniform(0, 255, (600, 800)).astype(np.float32)
    >>> pair = make_oblique_pair(img, 2.0, 4.0, np.random.default_rng(1), high_size=(120, 90))
    >>> sorted(np.round(1 / np.linalg.svd(pair.truth[:, :2])[1], 6).tolist())
    [0.5, 2.0]
    """
    photo = np.asarray(photo, dtype=np.float32)
    if not (ratio >= 1.0 and tilt >= 1.0):
        raise ValueError(f"ratio and tilt must be >= 1, got {ratio}, {tilt}")
    high_size = high_size or oblique_high_size(ratio, tilt)
    longitude = float(rng.uniform(*LONGITUDE_RANGE))
    # the photo turned by phi, then compressed along x: the oblique camera's frame is aligned
    # with its compression (a thin slanted band would hold no crop of a steep view)
    oblique, to_oblique = affine_warp(photo, tilted_linear(1.0, longitude, tilt, longitude))
    back = invert(to_oblique)
    ph, pw = photo.shape
    oh, ow = oblique.shape
    w, h = min(int(high_size[0]), ow // 2), min(int(high_size[1]), oh // 2)
    shrink = ratio / math.sqrt(tilt)
    best = None
    for _ in range(OBLIQUE_CROP_SHRINKS + 1):  # a smaller crop where the view is too narrow
        if min(w, h) < OBLIQUE_MIN_CROP_PX:
            break
        best = _crop_on_photo(oblique, back, (pw, ph), (w, h), shrink, rng)
        if best is not None:
            break
        w, h = int(w * 0.8), int(h * 0.8)
    if best is None:
        raise ValueError(f"photo {pw}x{ph} seen at tilt {tilt:g} holds no {w}x{h} crop; use a "
                         f"smaller high_size")
    x, y = best
    high = np.ascontiguousarray(oblique[y:y + h, x:x + w])
    angle = float(rng.uniform(*ANGLE_RANGE))
    gain, offset, noise_std = grey_change(rng)
    canvas, warp = zoom_warp(photo, ratio, angle)
    low, truth, window = cut_low(canvas, compose(warp, compose(back, _translation(x, y))),
                                 (w, h), low_max, gain, offset, noise_std, rng)
    return ZoomPair(low=low, high=high, truth=truth, ratio=float(ratio), angle_deg=angle,
                    gain=gain, offset=offset, noise_std=noise_std, source=source,
                    crop_xy=(x, y), window_xy=window, tilt=float(tilt), longitude_deg=longitude)


# --------------------------------------------------------------------------------------------
# Perspective zoom pairs: the local ratio varies across the footprint (docs/design/VIEWS.md)
# --------------------------------------------------------------------------------------------

#: Spreads of the perspective pairs: the local ratio's largest over its smallest value across
#: the high image's footprint (docs/design/VIEWS.md, "Perspective pairs")
SPREADS = (4.0, 8.0)
#: Pixels whose depth factor w (the homography's third coordinate, 1 at the crop's centre) is
#: below this are left out of the low image (black): near w = 0 lies the horizon, where the
#: photo would be shrunk without bound
PERSPECTIVE_MIN_W = 0.25
#: Anti-aliasing levels of a perspective pair: the photo blurred for local ratios a half
#: octave apart, blended per low pixel (the camera model of ``zoom_warp``, per pixel)
PERSPECTIVE_LEVEL_STEP = math.sqrt(2.0)


def perspective_homography(ratio: float, spread: float, angle_deg: float, direction_deg: float,
                           crop: Tuple[int, int, int, int]) -> Tuple[np.ndarray, np.ndarray, float]:
    """(H 3x3 photo px -> low px up to a shift, the depth gradient (gx, gy) per photo px, the
    local ratio at the crop's centre).

    ``H = (1 / r_c) R(theta) P T(-c)`` with ``c`` the crop's centre and ``P`` the projective map
    ``p -> p / w(p)``, ``w(p) = 1 + g . p``, ``g`` along ``direction_deg``. At a photo point the
    linear shrink is ``w`` across ``g`` and ``w^2`` along it, so the local ratio (high px per
    low px, geometric mean) is ``r_c w^1.5``. ``|g|`` is set so that it spans exactly
    ``[ratio, ratio * spread]`` over the crop: ``w`` spans ``[1 - a, 1 + a]`` with
    ``((1 + a) / (1 - a))^1.5 = spread``, and ``r_c = ratio / (1 - a)^1.5``.

    >>> h, g, rc = perspective_homography(2.0, 4.0, 0.0, 0.0, (0, 0, 641, 481))
    >>> w = lambda x: 1 + g[0] * (x - 320)
    >>> round(float(rc * w(0) ** 1.5), 6), round(float(rc * w(640) ** 1.5), 6)
    (2.0, 8.0)
    """
    x, y, w, h = crop
    cx, cy = x + (w - 1) / 2.0, y + (h - 1) / 2.0
    k = float(spread) ** (2.0 / 3.0)  # w's largest over its smallest value
    a = (k - 1.0) / (k + 1.0)
    u = np.array([math.cos(math.radians(direction_deg)), math.sin(math.radians(direction_deg))])
    half = abs(u[0]) * (w - 1) / 2.0 + abs(u[1]) * (h - 1) / 2.0  # largest u.(p - c) on the crop
    g = u * (a / half)
    r_c = float(ratio) / (1.0 - a) ** 1.5
    proj = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [g[0], g[1], 1.0]])
    shift = np.array([[1.0, 0.0, -cx], [0.0, 1.0, -cy], [0.0, 0.0, 1.0]])
    lin = np.eye(3)
    lin[:2, :2] = similarity_matrix(1.0 / r_c, angle_deg)[:, :2]
    return lin @ proj @ shift, g, r_c


def _clip_half_plane(poly: np.ndarray, g: np.ndarray, c: np.ndarray, w_min: float) -> np.ndarray:
    """The polygon (N, 2) cut to the half-plane ``1 + g.(p - c) >= w_min`` (Sutherland-Hodgman)."""
    out = []
    n = len(poly)
    for i in range(n):
        p, q = poly[i], poly[(i + 1) % n]
        fp, fq = 1 + g @ (p - c) - w_min, 1 + g @ (q - c) - w_min
        if fp >= 0:
            out.append(p)
        if (fp >= 0) != (fq >= 0):
            out.append(p + (q - p) * (fp / (fp - fq)))
    return np.array(out)


def blurred_warp(image: np.ndarray, m3: np.ndarray, size: Tuple[int, int],
                 level: np.ndarray) -> np.ndarray:
    """``image`` warped by the 3x3 map ``m3`` onto ``size`` (w, h), each output pixel blurred for
    its own local ratio: ``level`` (h, w), ``log_step`` of that ratio (``PERSPECTIVE_LEVEL_STEP``;
    0 for ratio 1). The image is blurred for the ratios ``step^j`` (the camera model of
    ``zoom_warp``), each warped, and every pixel blends the two levels around its own, linearly.

    >>> img = np.tile(np.float32([0, 255]), (40, 20))        # the finest stripes there are
    >>> flat = blurred_warp(img, np.eye(3), (40, 40), np.full((40, 40), 6.0))  # ratio 8
    >>> sharp = blurred_warp(img, np.eye(3), (40, 40), np.zeros((40, 40)))     # ratio 1
    >>> bool(np.ptp(flat[10:30, 10:30]) < 1.0), bool(np.ptp(sharp[10:30, 10:30]) == 255.0)
    (True, True)
    """
    w, h = size
    out = np.zeros((h, w), np.float32)
    top = int(np.ceil(level.max())) if level.size else 0
    below = None
    for j in range(top + 1):
        rho = PERSPECTIVE_LEVEL_STEP ** j
        sigma = CAMERA_BLUR_PX * math.sqrt(max(rho * rho - 1.0, 0.0))
        blurred = cv2.GaussianBlur(image, (0, 0), sigma) if sigma > 0.01 else image
        here = cv2.warpPerspective(blurred, m3, (w, h), flags=cv2.INTER_LINEAR,
                                   borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        if below is None:
            out[level <= 0] = here[level <= 0]
        else:  # pixels whose level lies in (j - 1, j]: the two levels blended
            sel = (level > j - 1) & (level <= j)
            f = (level - (j - 1)).astype(np.float32)
            out[sel] = ((1 - f) * below + f * here)[sel]
        below = here
    return out


def make_perspective_pair(photo: np.ndarray, ratio: float, spread: float,
                          rng: np.random.Generator, high_size: Tuple[int, int] = HIGH_SIZE,
                          low_max: Tuple[int, int] = LOW_MAX, source: str = "") -> ZoomPair:
    """A zoom pair seen in perspective: the local ratio grows from ``ratio`` to
    ``ratio * spread`` across the high image's footprint, exact homography truth
    (docs/design/VIEWS.md, "Perspective pairs").

    As ``make_tilted_pair`` (most textured of 6 crops, measured at the mean shrink
    ``ratio * sqrt(spread)``; grey-level change, noise, a window of at most ``low_max``), but the
    photo is mapped by ``perspective_homography`` (theta uniform in [-180, 180), the depth
    gradient's direction in [0, 360)), each low pixel blurred for its own local ratio (the photo
    blurred at levels ``PERSPECTIVE_LEVEL_STEP`` apart, blended), and photo points beyond
    ``PERSPECTIVE_MIN_W`` (towards the horizon) left black. ``truth`` is the 3x3 homography
    high px -> low px; ``tilt`` holds the spread. ``rng`` draws, in order: the crop positions,
    theta, the direction, gain, offset, noise std, the window offset and the noise.
    """
    photo = np.asarray(photo, dtype=np.float32)
    if not (ratio >= 1.0 and spread >= 1.0):
        raise ValueError(f"ratio and spread must be >= 1, got {ratio}, {spread}")
    crop = choose_crop(photo, ratio * math.sqrt(spread), rng, high_size)
    x, y, w, h = crop
    high = np.ascontiguousarray(photo[y:y + h, x:x + w])
    angle = float(rng.uniform(*ANGLE_RANGE))
    direction = float(rng.uniform(0.0, 360.0))
    gain, offset, noise_std = grey_change(rng)
    hom, g, r_c = perspective_homography(ratio, spread, angle, direction, crop)
    c = np.array([x + (w - 1) / 2.0, y + (h - 1) / 2.0])
    ph, pw = photo.shape
    frame = np.array([[0, 0], [pw - 1, 0], [pw - 1, ph - 1], [0, ph - 1]], dtype=np.float64)
    seen = _clip_half_plane(frame, g, c, PERSPECTIVE_MIN_W)  # the photo short of the horizon
    mapped = apply(hom, seen)
    origin = np.floor(mapped.min(axis=0))
    canvas = np.ceil(mapped.max(axis=0) - origin).astype(int) + 1
    to_canvas = np.array([[1.0, 0.0, -origin[0]], [0.0, 1.0, -origin[1]], [0.0, 0.0, 1.0]]) @ hom
    corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], dtype=np.float64)
    wx, wy, ww, wh = window_offset((int(canvas[0]), int(canvas[1])),
                                   apply(to_canvas, corners + [x, y]), low_max, rng)
    to_low = np.array([[1.0, 0.0, -wx], [0.0, 1.0, -wy], [0.0, 0.0, 1.0]]) @ to_canvas
    # every low pixel's photo point, its depth factor and its local ratio
    gx, gy = np.meshgrid(np.arange(ww, dtype=np.float64), np.arange(wh, dtype=np.float64))
    src = apply(np.linalg.inv(to_low), np.column_stack([gx.ravel(), gy.ravel()]))
    depth = (1.0 + (src - c) @ g).reshape(wh, ww)
    inside = ((src[:, 0] >= 0) & (src[:, 0] <= pw - 1) & (src[:, 1] >= 0)
              & (src[:, 1] <= ph - 1)).reshape(wh, ww) & (depth >= PERSPECTIVE_MIN_W)
    local = r_c * np.clip(depth, PERSPECTIVE_MIN_W, None) ** 1.5
    level = np.log(np.maximum(local, 1.0)) / math.log(PERSPECTIVE_LEVEL_STEP)
    # only the part of the photo the window sees is blurred (with room for the widest blur)
    src_in = src[inside.ravel()]
    top = int(np.ceil(level[inside].max())) + 1 if src_in.size else 1
    pad = int(np.ceil(4 * CAMERA_BLUR_PX * PERSPECTIVE_LEVEL_STEP ** top)) + 2
    x0, y0 = (np.maximum(np.floor(src_in.min(axis=0)) - pad, 0).astype(int) if src_in.size
              else (0, 0))
    x1, y1 = (np.minimum(np.ceil(src_in.max(axis=0)) + pad, [pw - 1, ph - 1]).astype(int) + 1
              if src_in.size else (pw, ph))
    m = to_low @ np.array([[1.0, 0.0, x0], [0.0, 1.0, y0], [0.0, 0.0, 1.0]])
    low = blurred_warp(photo[y0:y1, x0:x1], m, (ww, wh), np.minimum(level, top))
    low[~inside] = 0.0
    low = degrade(low, gain, offset, noise_std, rng)
    low[~inside] = 0.0
    truth = to_low @ np.array([[1.0, 0.0, x], [0.0, 1.0, y], [0.0, 0.0, 1.0]])
    return ZoomPair(low=low, high=high, truth=truth / truth[2, 2], ratio=float(ratio),
                    angle_deg=angle, gain=gain, offset=offset, noise_std=noise_std,
                    source=source, crop_xy=(x, y), window_xy=(wx, wy), tilt=float(spread),
                    longitude_deg=direction)


# --------------------------------------------------------------------------------------------
# A smooth scene: what starves a fixed-threshold detector (docs/design/DECISION.md,
# "Adaptive detection")
# --------------------------------------------------------------------------------------------

#: Period of the stripes of ``smooth_scene``, px, and the number of soft blobs on them
SMOOTH_STRIPE_PERIOD_PX = 160.0
SMOOTH_BLOBS = 6


def smooth_scene(shape: Tuple[int, int] = (480, 640), seed: int = 0) -> np.ndarray:
    """A smooth curved facade, float32 grey levels (h, w): wide soft stripes (tanh of a sine,
    +-50 grey levels about 128), ``SMOOTH_BLOBS`` Gaussian blobs of +-40, and 1 grey level of
    noise; deterministic from ``seed``. Few corners at any scale.
    """
    rng = np.random.default_rng(seed)
    h, w = shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    img = 128 + 50 * np.tanh(3 * np.sin(2 * np.pi * (x * 0.9 + y * 0.3)
                                        / SMOOTH_STRIPE_PERIOD_PX))
    for _ in range(SMOOTH_BLOBS):
        cx, cy, r = rng.uniform(0, w), rng.uniform(0, h), rng.uniform(30, 90)
        img += rng.uniform(-40, 40) * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * r * r))
    return np.clip(img + rng.normal(0, 1.0, img.shape), 0, 255).astype(np.float32)


# --------------------------------------------------------------------------------------------
# Crops with large flat or clipped regions (EVALUATION.md step 5): scene the no-data rule must
# not take for a canvas, and few points to match with
# --------------------------------------------------------------------------------------------

#: What fills the flat region of a flat pair's photo: ``clipped`` highlights (an overexposed
#: sky: the exposure rises across a soft edge until everything but the darkest pixels reaches
#: 255), a ``night`` sky (the scene crushed to a few grey levels), a studio ``backdrop`` (one
#: grey level, exactly flat, behind the scene's outline) and a plain ``sky`` (a smooth gradient
#: with sensor noise: flat, but not one level)
FLAT_KINDS = ("clipped", "night", "backdrop", "sky")
#: Share of the high crop the flat region covers, drawn in [lo, hi)
FLAT_SHARE_RANGE = (0.30, 0.50)
#: Ratios of the flat pairs (EVALUATION.md step 5: "at ratios 8 to 16 where points are scarce")
FLAT_RATIOS = (8.0, 10.0, 12.0, 16.0)
#: The region's outline wanders this far (photo px, peak) from a straight line, in
#: ``FLAT_WAVES`` sinusoids of wavelengths drawn in ``FLAT_WAVELENGTH_PX``: the outline of
#: rooftops, trees or a subject rather than a ruler's edge
FLAT_WAVE_PX = (25.0, 70.0)
FLAT_WAVES = 4
FLAT_WAVELENGTH_PX = (200.0, 900.0)
#: Width (photo px) of the soft edge across which a clipped or night exposure sets in
FLAT_EDGE_PX = 12.0
#: Exposure gain beyond a clipped region's edge (only pixels under 255 / (1 + gain) stay below
#: the clip: dark branches against a blown-out sky) and the factor of a night region
CLIP_GAIN = 8.0
NIGHT_FACTOR = 0.02
#: Grey level of a backdrop, drawn in [lo, hi); a sky's gradient runs between these levels
BACKDROP_LEVEL_RANGE = (200.0, 250.0)
SKY_LEVELS = (170.0, 225.0)
#: Sensor noise of a plain sky, grey levels (std)
SKY_NOISE_STD = 1.0


def flat_field(shape: Tuple[int, int], crop: Tuple[int, int, int, int], share: float,
               rng: np.random.Generator) -> np.ndarray:
    """(H, W) float32 signed distance, photo px, to a wavy outline: positive on the flat side.

    The outline runs across the photo at a random direction, wanders ``FLAT_WAVE_PX`` about a
    straight line, and is placed so that ``share`` of the crop ``(x, y, w, h)`` lies on the flat
    side (which then touches the crop's border). ``rng`` draws the direction, the amplitude,
    then each wave's wavelength and phase.
    """
    h, w = shape
    theta = float(rng.uniform(0.0, 2.0 * math.pi))
    amp = float(rng.uniform(*FLAT_WAVE_PX))
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    u = xx * math.cos(theta) + yy * math.sin(theta)
    v = -xx * math.sin(theta) + yy * math.cos(theta)
    wave = np.zeros_like(u)
    for _ in range(FLAT_WAVES):
        length = float(rng.uniform(*FLAT_WAVELENGTH_PX))
        phase = float(rng.uniform(0.0, 2.0 * math.pi))
        wave += np.sin(v * np.float32(2.0 * math.pi / length) + np.float32(phase))
    d = u + np.float32(amp / math.sqrt(FLAT_WAVES / 2.0)) * wave
    x, y, cw, ch = crop
    level = float(np.quantile(d[y:y + ch, x:x + cw], 1.0 - share))
    return d - np.float32(level)


def flatten(photo: np.ndarray, d: np.ndarray, kind: str, rng: np.random.Generator) -> np.ndarray:
    """``photo`` with the flat side of ``d`` (``flat_field``) made flat as ``kind`` says
    (``FLAT_KINDS``), rounded to whole grey levels in 0..255, float32. ``rng`` draws a
    backdrop's level or a sky's noise."""
    img = np.asarray(photo, np.float32)
    if kind in ("clipped", "night"):
        step = 1.0 / (1.0 + np.exp(np.clip(-d / np.float32(FLAT_EDGE_PX / 4.0), -50, 50)))
        factor = 1.0 + CLIP_GAIN * step if kind == "clipped" else 1.0 - (1.0 - NIGHT_FACTOR) * step
        out = img * factor
    elif kind == "backdrop":
        inside = np.clip(d + 0.5, 0.0, 1.0)  # one pixel of anti-aliasing along the outline
        out = img * (1.0 - inside) + np.float32(rng.uniform(*BACKDROP_LEVEL_RANGE)) * inside
    elif kind == "sky":
        inside = np.clip(d + 0.5, 0.0, 1.0)
        lo, hi = SKY_LEVELS
        ramp = np.float32(lo) + np.float32(hi - lo) * np.clip(d / max(float(d.max()), 1.0), 0, 1)
        sky = ramp + rng.normal(0.0, SKY_NOISE_STD, d.shape).astype(np.float32)
        out = img * (1.0 - inside) + sky * inside
    else:
        raise ValueError(f"kind must be one of {FLAT_KINDS}, got {kind!r}")
    return np.clip(np.rint(out), 0, 255).astype(np.float32)


def make_flat_pair(photo: np.ndarray, ratio: float, kind: str, rng: np.random.Generator,
                   high_size: Optional[Tuple[int, int]] = None, low_max: Tuple[int, int] = LOW_MAX,
                   source: str = "") -> ZoomPair:
    """A zoom pair whose high crop is ``FLAT_SHARE_RANGE`` flat or clipped (EVALUATION.md step
    5), with exact ground truth.

    The crop is chosen as ``make_zoom_pair`` chooses it (the most textured of 6, so the rest of
    it holds texture); the photo is then flattened beyond a wavy outline across the crop
    (``flat_field``, ``flatten``), and the pair is cut from the flattened photo
    (``zoom_pair_from_crop``): the low image sees the same flat region. ``rng`` draws the crop
    positions, the share, the outline, the fill, then what ``zoom_pair_from_crop`` draws.
    """
    photo = np.asarray(photo, np.float32)
    crop = choose_crop(photo, ratio, rng, high_size or high_size_for(ratio))
    share = float(rng.uniform(*FLAT_SHARE_RANGE))
    flat = flatten(photo, flat_field(photo.shape, crop, share, rng), kind, rng)
    return zoom_pair_from_crop(flat, crop, ratio, rng, low_max, source)


# --------------------------------------------------------------------------------------------
# A 3-D scene: two planes at two depths, seen from two places
# --------------------------------------------------------------------------------------------

#: the finer camera's focal length, px (a 640 px wide image: a 50 degree field of view)
TWO_PLANES_FOCAL_PX = 700.0
#: the coarser camera's frame, beyond the finer image's footprint, px (width, height)
TWO_PLANES_MARGIN_PX = (80, 60)


@dataclass(frozen=True, eq=False)
class TwoPlanePair:
    """A 3-D pair with exact ground truth: ``high`` shows two fronto-parallel planes side by side
    (its left half at the first depth, its right half at the second); ``low`` is the scene from
    a camera moved by ``baseline`` (depth units) and turned, with ``ratio`` times the focal
    length's resolution less."""

    low: np.ndarray = field(repr=False)
    high: np.ndarray = field(repr=False)
    #: x_low^T F x_high = 0 (px of each image)
    fundamental: np.ndarray = field(repr=False)
    #: each plane's map, high px -> low px (left half, right half)
    homographies: Tuple[np.ndarray, np.ndarray] = field(repr=False)

    def low_point(self, xy_high: np.ndarray) -> np.ndarray:
        """Where the scene points seen at ``xy_high`` ((N, 2) high px) appear in ``low``."""
        xy = np.asarray(xy_high, np.float64).reshape(-1, 2)
        left = xy[:, 0] < self.high.shape[1] / 2
        return np.where(left[:, None], apply(self.homographies[0], xy),
                        apply(self.homographies[1], xy))


def make_two_plane_pair(high: np.ndarray, ratio: float = 2.0, baseline: float = 0.6,
                        depths: Tuple[float, float] = (5.0, 8.0),
                        turn_deg: float = 4.0) -> TwoPlanePair:
    """A 3-D pair cut from one grey image ``high`` (its texture painted on two planes at
    ``depths``, the left and right halves): the low camera moved sideways by ``baseline``
    (and a twentieth of it down), turned by ``turn_deg`` about the vertical, its focal length
    ``ratio`` times shorter; ``low`` blurred by the camera model before it is sampled.

    Each plane maps high px to low px by ``K_low (R + t n^T / d) K_high^-1`` and the pair's
    epipolar geometry is ``F = K_low^-T [t]_x R K_high^-1`` (Hartley & Zisserman, 13.1 and
    9.2.2)."""
    high = np.asarray(high, np.float32)
    h, w = high.shape
    k_high = np.array([[TWO_PLANES_FOCAL_PX, 0, w / 2], [0, TWO_PLANES_FOCAL_PX, h / 2],
                       [0, 0, 1]])
    lw, lh = int(w / ratio) + TWO_PLANES_MARGIN_PX[0], int(h / ratio) + TWO_PLANES_MARGIN_PX[1]
    k_low = np.array([[TWO_PLANES_FOCAL_PX / ratio, 0, lw / 2],
                      [0, TWO_PLANES_FOCAL_PX / ratio, lh / 2], [0, 0, 1]])
    a = math.radians(turn_deg)
    r = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    t = np.array([baseline, baseline / 20.0, 0.0])
    blurred = cv2.GaussianBlur(high, (0, 0), CAMERA_BLUR_PX * math.sqrt(ratio ** 2 - 1))
    low = np.zeros((lh, lw), np.float32)
    maps = []
    for i, depth in enumerate(depths):
        hm = k_low @ (r + np.outer(t, (0.0, 0.0, 1.0)) / depth) @ np.linalg.inv(k_high)
        half = np.zeros((h, w), np.float32)
        half[:, i * w // 2:(i + 1) * w // 2] = 1.0
        seen = cv2.warpPerspective(half, hm, (lw, lh), flags=cv2.INTER_LINEAR) > 0.5
        low = np.where(seen, cv2.warpPerspective(blurred, hm, (lw, lh), flags=cv2.INTER_AREA),
                       low)
        maps.append(hm / hm[2, 2])
    cross = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    f = np.linalg.inv(k_low).T @ cross @ r @ np.linalg.inv(k_high)
    return TwoPlanePair(low, high, f / np.linalg.norm(f), (maps[0], maps[1]))
