"""The overlay of a match: the finer image warped by ``result.transform`` onto the coarser one in
false colour (low in magenta, warped high in green: grey where they agree, coloured fringes where
they do not) with the footprint of the high-resolution image outlined, so a person sees at a
glance whether the transform fits.

* ``overlay``: the picture, between its caption bands (the verdict above, the files below);
  a small footprint's region enlarged in an inset (``inset_plan``), a "no"'s refused candidate
  dashed (``rejected_footprint``), a fundamental matrix's inliers and epipolar lines;
* ``overlay_zoom``, ``enlarged``, ``overlay_footer``: a small coarser image drawn enlarged, and
  the footer that names the files.

Conventions as in ``result``: OpenCV pixels (centres at integers), ``transform`` maps a
high-resolution pixel to a low-resolution pixel (2x3 or 3x3). The image edge of a W x H image
runs through (-0.5, -0.5) .. (W - 0.5, H - 0.5); that is the footprint outline drawn.
"""

from __future__ import annotations

import math
from typing import Optional, Sequence, Tuple

import cv2
import numpy as np

from .captions import band
from .geometry import as_matrix3, footprint, resize_map, similarity_parts
from .greylevels import to_bgr8
from .result import MatchResult
from .stages.estimator import model_of
from .stages.nodata import NoDataParams, valid_mask
from .verdict import evidence_line, verdict

#: Footprint outline colour (BGR) and the false colours of the overlay.
#: blur of the enlarged overlay's finer image, in the low image's px: the camera model of
#: EVALUATION.md (0.5 px), for the picture only
DRAWN_CAMERA_BLUR_PX = 0.5
OUTLINE = (0, 215, 255)  # amber
#: an inlier's dot (the matches picture's too)
INLIER_DOT = (0, 215, 255)
#: the fundamental matrix's picture: the epipolar lines of this many inliers, in this colour
EPIPOLAR_LINES_DRAWN = 8
EPIPOLAR_LINE = (255, 160, 0)
#: A "no"'s refused candidate: its footprint dashed in red (BGR; its inliers greyed in the
#: matches picture, ``render.REJECTED_DOT``)
REJECTED = (60, 60, 255)
#: The frames of the inset and of the region it enlarges (BGR)
INSET_FRAME = (255, 255, 255)
#: Weight of the low image outside the footprint (dimmed so the footprint stands out).
OUTSIDE_DIM = 0.55
#: Footprint outline thickness per pixel of the picture's shorter side (at least 2 px).
OUTLINE_PER_PX = 1.0 / 300
#: Radius of an inlier's circle on a fundamental matrix's overlay, in outline thicknesses
#: (:func:`_outline_thickness`): 3 px circles of 1 px were specks on a 2,500 px picture seen
#: whole; sized with the picture, they read the same at any size (at least 6 px, 2 px thick)
DOT_RADIUS_PER_THICKNESS = 3
#: A footprint narrower and lower than this share of the picture gets an inset: its region
#: enlarged in a free corner. At ratio 8 to 16 the finer image covers a few hundredths of the
#: coarser one, too little to see whether the two agree
INSET_MAX_SHARE = 0.25
#: The inset's side, as a share of the picture's shorter side
INSET_SHARE = 0.4
#: The region shown around the footprint, as a multiple of its longer side
INSET_CONTEXT = 1.5
#: Smallest enlargement worth an inset
INSET_MIN_ZOOM = 2.0
#: Radius of the dot on the footprint's top-left corner, in outline thicknesses
CORNER_DOT_PER_THICKNESS = 3
#: A coarser image whose longer side is under this is drawn enlarged by a whole factor in the
#: overlay (the finer image warped onto the enlarged grid, so its detail shows): at its own
#: 185 x 171 px, the verdict wrapped into six lines of minimal text over a thumbnail
MIN_OVERLAY_SIDE_PX = 600


def _warp_high(high_grey: np.ndarray, transform: np.ndarray, size: Tuple[int, int],
               nodata: NoDataParams = NoDataParams()) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """high warped onto a ``size`` (w, h) canvas by ``transform``: (image, footprint mask 0/255,
    mask 0/255 of where high shows the scene, not a no-data canvas: ``nodata.valid_mask``).

    The high image is first shrunk by INTER_AREA to about the target resolution so the warp does
    not alias (a plain bilinear warp at 10x shrink keeps 1 pixel in 100); its no-data is found
    on that shrunk copy.
    """
    ratio, _, _ = similarity_parts(transform)
    t3 = as_matrix3(transform)
    img = high_grey
    f = 1.0 / ratio if np.isfinite(ratio) and ratio > 1.0 else 1.0
    if f < 0.9:
        h, w = img.shape[:2]
        sw, sh = max(int(round(w * f)), 1), max(int(round(h * f)), 1)
        img = cv2.resize(img, (sw, sh), interpolation=cv2.INTER_AREA)
        fx, fy = sw / w, sh / h
        # small px -> high px: x_high = (x_small + 0.5) / fx - 0.5
        back = as_matrix3(resize_map(1 / fx, 1 / fy))
        t3 = t3 @ back
    ones = np.full(img.shape[:2], 255, np.uint8)
    valid = valid_mask(img, nodata)
    scene = ones if valid is None else valid.astype(np.uint8) * 255

    def warp(a: np.ndarray, flags: int) -> np.ndarray:
        if np.asarray(transform).shape == (2, 3):
            return cv2.warpAffine(a, t3[:2], size, flags=flags)
        return cv2.warpPerspective(a, t3, size, flags=flags)

    return warp(img, cv2.INTER_LINEAR), warp(ones, cv2.INTER_NEAREST), warp(scene, cv2.INTER_NEAREST)


def match_grey_levels(image: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``image`` (uint8) brought to ``reference``'s grey levels over ``mask``: the gain and offset
    that give it the reference's mean and standard deviation there (the two photos of a pair
    differ by exposure; without this the overlay's blend reads as colour where the pixels
    agree). Unchanged where either is flat or the mask is empty.

    >>> ref = np.arange(0, 200, 2, dtype=np.uint8).reshape(10, 10)
    >>> img = (ref // 2 + 60).astype(np.uint8)          # half the contrast, brighter
    >>> out = match_grey_levels(img, ref, np.ones(ref.shape, bool))
    >>> int(np.abs(out.astype(int) - ref).max()) <= 1
    True
    """
    if not mask.any():
        return image
    a = image[mask].astype(np.float64)
    b = reference[mask].astype(np.float64)
    if a.std() < 1e-6 or b.std() < 1e-6:
        return image
    gain = b.std() / a.std()
    out = (image.astype(np.float64) - a.mean()) * gain + b.mean()
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def overlay(low: np.ndarray, high: np.ndarray, result: MatchResult,
            footer: Sequence[str] = (), enlarged_by: int = 1) -> np.ndarray:
    """The high image warped onto the low one, false-colour blended, footprint outlined.

    Parameters
    ----------
    low : (H, W) or (H, W, 3) array
        The low-resolution image (grey levels or BGR); the output has its size.
    high : (h, w) or (h, w, 3) array
        The high-resolution image.
    result : MatchResult
        When matched with a 2x3 or 3x3 transform: warp, blend and outline. For the fundamental
        matrix (no point-to-point map) the inliers are drawn on ``low``. When not matched,
        ``low`` with a "no reliable match: reason" caption.
    footer : sequence of str
        Lines of a caption at the bottom (``write_outputs``: the files' names). The outline is
        drawn over both captions, so the strips never hide it.
    enlarged_by : int
        ``low`` is its image enlarged this many times (:func:`enlarged`): the warped high image
        is blurred as much as the enlargement blurs the low one's pixels, so that where they
        agree they read grey (sharper, it fringes every edge in colour).

    Returns
    -------
    (H + bands, W, 3) uint8 array, BGR: the picture (H, W) between the caption bands, the
    verdict's above it and ``footer``'s below (none without a footer)
    """
    low_bgr = to_bgr8(low)
    low_grey = cv2.cvtColor(low_bgr, cv2.COLOR_BGR2GRAY)
    out = cv2.cvtColor(low_grey, cv2.COLOR_GRAY2BGR)
    t = None if result.transform is None else np.asarray(result.transform, dtype=np.float64)
    lines = [verdict(result), evidence_line(result)]
    outline = None  # (M, 1, 2) int32 in 1/16 px, and its thickness: drawn over the caption
    # a match warps the finer image where the model gives it a footprint (a map); a matrix's
    # inliers are drawn as dots
    if result.matched and t is not None and \
            model_of(result.model).footprint(t, high.shape) is not None:
        out, outline, legend = _blended(low_grey, high, t, enlarged_by, _nodata_rule(result))
        lines.append(legend)
        plan = inset_plan(outline, out.shape[:2]) if outline is not None else None
        if plan is not None:
            lines.append(f"inset: the footprint's region enlarged {plan[1]:.0f}x")
        return _captioned(out, lines, footer, outline, plan)
    elif not result.matched and rejected_footprint(result, high.shape) is not None:
        lines.append(_draw_rejected(out, result, high.shape))
    elif result.matched and result.inliers.size:
        lines.append(_draw_inlier_dots(out, result))
    return _captioned(out, lines, footer, outline)


def _outline_thickness(hh: int, ww: int) -> int:
    """The footprint outline's thickness on an ``hh`` x ``ww`` picture, px."""
    return max(2, int(round(min(hh, ww) * OUTLINE_PER_PX)))


def _nodata_rule(result: MatchResult) -> NoDataParams:
    """The no-data rule the match ran with (the default when its config is not a Config)."""
    return getattr(result.config, "nodata", None) or NoDataParams()


def _blended(low_grey: np.ndarray, high: np.ndarray, t: np.ndarray, enlarged_by: int = 1,
             nodata: NoDataParams = NoDataParams()):
    """(picture, outline, legend): the high image warped by ``t`` onto ``low_grey`` in false
    colour, the low image dimmed outside the footprint; the footprint's outline to draw over
    the caption (None: no footprint), and the caption line that explains the colours."""
    hh, ww = low_grey.shape[:2]
    high_grey = cv2.cvtColor(to_bgr8(high), cv2.COLOR_BGR2GRAY)
    warped, mask, scene = _warp_high(high_grey, t, (ww, hh), nodata)
    if enlarged_by > 1:  # the low image's camera blur, in the enlarged grid's px
        warped = cv2.GaussianBlur(warped, (0, 0), DRAWN_CAMERA_BLUR_PX * enlarged_by)
    inside = mask > 0
    # grey where they agree: the levels matched where both show the scene (a canvas's black
    # corners would pull the gain and offset, and the whole overlay would read as one colour)
    both = inside & (scene > 0)
    low_valid = valid_mask(low_grey, nodata)
    if low_valid is not None:
        both &= low_valid
    warped = match_grey_levels(warped, low_grey, both if both.any() else inside)
    dim = (low_grey.astype(np.float32) * OUTSIDE_DIM).astype(np.uint8)
    out = cv2.cvtColor(dim, cv2.COLOR_GRAY2BGR)
    out[inside, 0] = low_grey[inside]  # B: low
    out[inside, 1] = warped[inside]  # G: high, warped
    out[inside, 2] = low_grey[inside]  # R: low
    outline, clipped = _footprint_outline(t, high.shape, (hh, ww))
    legend = ("magenta = low, green = high warped (grey where they agree); "
              "outline = high footprint, dot = its top-left corner" +
              (" (cut at the picture's edge, where it runs beyond)" if clipped else ""))
    return out, outline, legend


def _footprint_outline(t: np.ndarray, high_shape, picture_shape: Tuple[int, int]):
    """(outline, clipped): the footprint of ``t`` cut to the picture (``picture_shape``, (H, W))
    with its whole stroke inside, as (M, 1, 2) int32 in 1/16 px, its thickness and where the
    high image's top-left corner falls ((x, y) in 1/16 px; None outside the picture), so that
    a turn of more than 90 degrees reads off the picture (None: no footprint, or none of it in
    the picture); True when it was cut."""
    corners = footprint(t, high_shape)
    if corners is None:
        return None, False
    hh, ww = picture_shape
    thick = _outline_thickness(hh, ww)
    inset = thick / 2.0  # the whole stroke inside the picture
    shown = clip_polygon(np.asarray(corners, np.float64),
                         (inset - 0.5, inset - 0.5, ww - 0.5 - inset, hh - 0.5 - inset))
    clipped = not np.allclose(shown.shape, np.asarray(corners).shape) or \
        not np.allclose(shown, corners)
    if len(shown) < 2:
        return None, clipped
    x0, y0 = corners[0]  # footprint's corners run clockwise from the top-left
    corner = (int(round(x0 * 16)), int(round(y0 * 16))) \
        if -0.5 <= x0 <= ww - 0.5 and -0.5 <= y0 <= hh - 0.5 else None
    return (np.round(shown * 16).astype(np.int32).reshape(-1, 1, 2), thick, corner), clipped


def _draw_rejected(out: np.ndarray, result: MatchResult, high_shape) -> str:
    """Dash the refused candidate's footprint on ``out``; the caption line that says so."""
    hh, ww = out.shape[:2]
    corners = rejected_footprint(result, high_shape)
    thick = _outline_thickness(hh, ww)
    dashed_polygon(out, corners, REJECTED, thick, dash_px=max(8, 4 * thick))
    return (f"dashed = the best candidate's footprint ({result.rejected.n_inliers} "
            f"inliers), refused by the {result.rejected.test} test")


def _draw_inlier_dots(out: np.ndarray, result: MatchResult) -> str:
    """Circle the inliers in the low image on ``out`` (a model with no overlay, the fundamental
    matrix), and draw the epipolar lines of ``EPIPOLAR_LINES_DRAWN`` of them, spread over
    the list; the caption line that says so."""
    pairs = np.asarray(result.inliers, np.float64).reshape(-1, 4)
    thick = _outline_thickness(*out.shape[:2])
    for x, y in pairs[:, 2:4]:
        cv2.circle(out, (int(round(x * 16)), int(round(y * 16))),
                   DOT_RADIUS_PER_THICKNESS * thick * 16, INLIER_DOT, thick, cv2.LINE_AA, shift=4)
    shown = np.unique(np.linspace(0, len(pairs) - 1, EPIPOLAR_LINES_DRAWN).round().astype(int))
    lines = 0
    for x, y in pairs[shown, :2] if len(pairs) else ():
        ends = line_ends(np.asarray(result.transform, np.float64) @ (x, y, 1.0),
                         (out.shape[1], out.shape[0]))
        if ends is not None:
            cv2.line(out, ends[0], ends[1], EPIPOLAR_LINE, max(1, thick // 2), cv2.LINE_AA)
            lines += 1
    return (f"dots = inliers in the low image, lines = the epipolar lines of {lines} of them "
            f"(a {result.model} matrix has no overlay)")


def line_ends(line: np.ndarray, size: Tuple[int, int]) -> Optional[Tuple[Tuple[int, int], ...]]:
    """The two ends, whole px, of the part of ``line`` (a, b, c: ax + by + c = 0) inside an
    image of ``size`` (W, H); None when it misses the image.

    >>> line_ends(np.array([0.0, 1, -5]), (10, 10))   # y = 5
    ((0, 5), (9, 5))
    """
    a, b, c = (float(v) for v in line)
    w, h = size
    big = 4.0 * (w + h)
    if abs(b) >= abs(a):
        p, q = (-big, (-c + a * big) / b), (big, (-c - a * big) / b)
    else:
        p, q = ((-c + b * big) / a, -big), ((-c - b * big) / a, big)
    ok, p1, p2 = cv2.clipLine((0, 0, w, h), tuple(int(round(v)) for v in p),
                              tuple(int(round(v)) for v in q))
    return (tuple(p1), tuple(p2)) if ok else None


def _captioned(out: np.ndarray, lines: Sequence[str], footer: Sequence[str],
               outline, inset=None) -> np.ndarray:
    """``out`` with the footprint ``outline`` drawn on it, between its caption ``lines`` in a
    band above and ``footer`` in a band below: the captions never cover the picture (drawn
    over it, they took 30-40 % of a 3:2 picture's height at any size, and hid a footprint's
    corner and its dot). ``inset``: the :func:`inset_plan` of a small footprint, its region
    drawn enlarged in a free corner."""
    ww = out.shape[1]
    detail = out.copy() if inset is not None else None  # the picture the inset enlarges
    if outline is not None:
        _draw_outline(out, outline)
    if detail is not None:
        _place_inset(out, detail, inset[0], inset[1], 0, 0, outline)
    return np.vstack([band(lines, ww), out] + ([band(footer, ww)] if any(footer) else []))


def _draw_outline(out: np.ndarray, outline) -> None:
    """The footprint's outline and the dot on the finer image's top-left corner, on ``out``."""
    cv2.polylines(out, [outline[0]], True, OUTLINE, outline[1], cv2.LINE_AA, shift=4)
    if outline[2] is not None:
        cv2.circle(out, outline[2], 16 * CORNER_DOT_PER_THICKNESS * outline[1], OUTLINE, -1,
                   cv2.LINE_AA, shift=4)


def inset_plan(outline, shape: Tuple[int, int]):
    """(region, zoom) of the inset of a small footprint, or None: ``region`` (x0, y0, x1, y1)
    px, a square of ``INSET_CONTEXT`` times the footprint's longer side around it (moved to lie
    inside the picture of ``shape``, (H, W)), drawn ``zoom`` times larger, to ``INSET_SHARE`` of
    the picture's shorter side. None when the footprint spans more than ``INSET_MAX_SHARE`` of
    the picture's width or height, or the enlargement would be under ``INSET_MIN_ZOOM``.

    >>> box = np.array([[400, 400], [560, 400], [560, 480], [400, 480]])  # 10 x 5 px, x 16
    >>> inset_plan((box.reshape(-1, 1, 2), 2, None), (600, 800))  # 16 px at least, 240 px
    ((22, 20, 38, 36), 15.0)
    """
    hh, ww = shape
    pts = np.asarray(outline[0], np.float64).reshape(-1, 2) / 16.0
    (x0, y0), (x1, y1) = pts.min(axis=0), pts.max(axis=0)
    if x1 - x0 > INSET_MAX_SHARE * ww or y1 - y0 > INSET_MAX_SHARE * hh:
        return None
    side = int(min(max(INSET_CONTEXT * max(x1 - x0, y1 - y0), 16.0), ww, hh))
    zoom = int(INSET_SHARE * min(ww, hh)) / side
    if zoom < INSET_MIN_ZOOM:
        return None
    left = int(np.clip(round((x0 + x1) / 2 - side / 2), 0, ww - side))
    top = int(np.clip(round((y0 + y1) / 2 - side / 2), 0, hh - side))
    return (left, top, left + side, top + side), zoom


def _place_inset(out: np.ndarray, picture: np.ndarray, region: Tuple[int, int, int, int],
                 zoom: float, top: int, bottom: int, outline) -> None:
    """``region`` of ``picture`` enlarged ``zoom`` times, in the corner of ``out`` between the
    caption strips (``top``, ``bottom`` px) farthest from the region, framed, with the
    footprint ``outline`` drawn at the inset's scale in the picture's stroke; the region framed
    where it is. Nothing when no corner clears the region."""
    hh, ww = out.shape[:2]
    x0, y0, x1, y1 = region
    side = int(round((x1 - x0) * zoom))
    pad = max(4, _outline_thickness(hh, ww) * 2)
    if side + 2 * pad > hh - top - bottom:
        return
    spots = [(x, y) for x in (pad, ww - pad - side) for y in (top + pad, hh - bottom - pad - side)]
    clear = [(x, y) for x, y in spots
             if x + side + pad <= x0 or x - pad >= x1 or y + side + pad <= y0 or y - pad >= y1]
    if not clear:
        return
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    x, y = max(clear, key=lambda p: (p[0] + side / 2 - cx) ** 2 + (p[1] + side / 2 - cy) ** 2)
    enlarged_region = cv2.resize(picture[y0:y1, x0:x1], (side, side),
                                 interpolation=cv2.INTER_CUBIC)
    if outline is not None:  # 1/16 px of the picture -> 1/16 px of the inset
        def moved(p):
            return np.round((np.asarray(p, np.float64) - 16.0 * np.array([x0, y0])) * zoom
                            ).astype(np.int32)
        _draw_outline(enlarged_region, (moved(outline[0].reshape(-1, 2)).reshape(-1, 1, 2),
                                        outline[1], None if outline[2] is None
                                        else tuple(int(v) for v in moved(outline[2]))))
    out[y:y + side, x:x + side] = enlarged_region
    line = max(1, _outline_thickness(hh, ww) // 2)
    cv2.rectangle(out, (x - line, y - line), (x + side + line - 1, y + side + line - 1),
                  INSET_FRAME, line)
    cv2.rectangle(out, (x0, y0), (x1 - 1, y1 - 1), INSET_FRAME, line)


def clip_polygon(points: np.ndarray, box: Tuple[float, float, float, float]) -> np.ndarray:
    """The polygon ``points`` (N, 2) cut to the rectangle ``box`` (x0, y0, x1, y1)
    (Sutherland-Hodgman): where it runs beyond the box, its outline follows the box's edge,
    so a footprint larger than the picture still shows. (M, 2); empty when none of it is inside.

    >>> clip_polygon(np.array([[-5., -5], [15, -5], [15, 15], [-5, 15]]), (0, 0, 10, 10)).tolist()
    [[0.0, 10.0], [0.0, 0.0], [10.0, 0.0], [10.0, 10.0]]
    """
    out = [np.asarray(p, np.float64) for p in points]
    x0, y0, x1, y1 = box
    edges = ((0, x0, 1), (0, x1, -1), (1, y0, 1), (1, y1, -1))  # axis, bound, inward sign
    for axis, bound, sign in edges:
        src, out = out, []
        for i, cur in enumerate(src):
            prev = src[i - 1]
            cur_in = sign * (cur[axis] - bound) >= 0
            prev_in = sign * (prev[axis] - bound) >= 0
            if cur_in != prev_in:
                f = (bound - prev[axis]) / (cur[axis] - prev[axis])
                out.append(prev + f * (cur - prev))
            if cur_in:
                out.append(cur)
        if not out:
            break
    return np.array(out, np.float64).reshape(-1, 2)


def drawn_note(factor: float, name: str = "low") -> str:
    """The overlay footer's note when the low image is drawn at another size than its file's
    (``factor``: file px per drawn px; ``name``: what the footer calls it): the overlay has the size of the low image as drawn (the
    high one is warped onto it at that size, so how it was decoded does not show).

    >>> drawn_note(2.0), drawn_note(1.0), drawn_note(0.25)
    ('   low drawn at 1/2 of its file size', '', '   low drawn 4x enlarged')
    """
    if factor == 1.0:
        return ""
    if factor < 1.0:
        return f"   {name} drawn {1.0 / factor:g}x enlarged"
    return f"   {name} drawn at 1/{factor:g} of its file size"


def overlay_footer(low_name: str, high_name: str, turned: bool, factor: float) -> str:
    """The overlay's footer: which file is drawn as which, and how the coarser one is drawn.

    ``low_name``, ``high_name``: the files drawn as the coarser and as the finer image. A match
    names them low and high, as its JSON does (the coarser and the finer image as found). A "no"
    whose refused candidate takes the images the other way round from the order given
    (``turned``; its JSON keeps the order given) names them by their part in the picture, so
    the second file given is never called "low".

    >>> overlay_footer("a.png", "b.png", False, 1.0)
    'low: a.png   high: b.png'
    >>> overlay_footer("b.png", "a.png", True, 1.0)
    'coarser: b.png   finer: a.png   (the refused candidate takes the second image given as the coarser one)'
    """
    if turned:
        return (f"coarser: {low_name}   finer: {high_name}   (the refused candidate takes the "
                f"second image given as the coarser one){drawn_note(factor, 'coarser')}")
    return f"low: {low_name}   high: {high_name}{drawn_note(factor)}"


def overlay_zoom(shape) -> int:
    """The whole factor the overlay enlarges a coarser image of ``shape`` by: the least that
    brings its longer side to ``MIN_OVERLAY_SIDE_PX`` (1 when it is there already).

    >>> overlay_zoom((171, 185)), overlay_zoom((377, 419)), overlay_zoom((768, 1024))
    (4, 2, 1)
    """
    side = max(int(shape[0]), int(shape[1]), 1)
    return max(1, int(math.ceil(MIN_OVERLAY_SIDE_PX / side)))


def enlarged(image: np.ndarray, zoom: int) -> np.ndarray:
    """``image`` enlarged ``zoom`` times, centre-aligned as ``cv2.resize`` (the grid
    :func:`scalematch.working.in_decoded` maps to with a factor of 1 / ``zoom``)."""
    h, w = image.shape[:2]
    return cv2.resize(image, (w * zoom, h * zoom), interpolation=cv2.INTER_CUBIC)


def rejected_footprint(result: MatchResult, high_shape) -> "np.ndarray | None":
    """(4, 2) the footprint of a "no"'s refused candidate in the coarser image, or None (a
    match, no candidate, a fundamental matrix, a corner at infinity)."""
    rej = result.rejected
    if result.matched or rej is None:
        return None
    return model_of(rej.model).footprint(np.asarray(rej.transform, np.float64), high_shape)


def dashed_polygon(image: np.ndarray, corners: np.ndarray, colour, thick: int,
                   dash_px: float) -> None:
    """Draw the closed polygon ``corners`` (N, 2) dashed onto ``image`` (in place): dashes of
    ``dash_px`` with gaps as long, anti-aliased, at sub-pixel precision."""
    pts = np.asarray(corners, np.float64)
    for a, b in zip(pts, np.roll(pts, -1, axis=0)):
        length = float(np.hypot(*(b - a)))
        steps = np.arange(0.0, length, 2.0 * dash_px)
        for start in steps:
            p = a + (b - a) * (start / max(length, 1e-9))
            q = a + (b - a) * (min(start + dash_px, length) / max(length, 1e-9))
            cv2.line(image, tuple(int(round(v * 16)) for v in p),
                     tuple(int(round(v * 16)) for v in q), colour, thick, cv2.LINE_AA, shift=4)
