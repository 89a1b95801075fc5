"""Stage 1: the scale-space of the high-resolution image (docs/ALGORITHM.md step 1, paper section 3.2).

At scale ``s`` the paper smooths the full-resolution image with Gaussians of std ``s*sigma``
(derivation) and ``s*sigma~`` (integration). Computing that at full resolution for s = 8 costs
64 times more pixels than needed, so each scale is computed on a *decimated* copy of the image:

* the copy at decimation ``d`` has been blurred by ``antialias_sigma(d)`` full-resolution pixels
  (the camera model of EVALUATION.md: about 0.5 px of blur once shrunk) and resampled so that
  decimated pixel ``x_d`` sits at full-resolution ``d * x_d + (d - 1) / 2`` (the centre-aligned
  convention of ``cv2.resize``);
* a Gaussian of total std ``S`` full-resolution pixels is then obtained on the copy with the std
  ``sqrt(S**2 - antialias_sigma(d)**2) / d`` decimated pixels (Gaussian blurs add in quadrature),
  so the response is the same up to sampling.

Levels are produced one at a time from the previous one (a cascade), so memory never holds more
than two levels and the large scales cost almost nothing.

Pixel convention: OpenCV's, x to the right, y down, pixel centres at integer coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator, Sequence

import cv2
import numpy as np

from ..geometry import apply, resize_map

def antialias_sigma(d: float, camera_blur_px: float = 0.5) -> float:
    """Blur (full-resolution px) applied before decimating by ``d``: ``camera_blur_px *
    sqrt(d^2 - 1)``, so that the decimated copy carries a camera blur of ``camera_blur_px`` of
    its own pixels (``HarrisParams.camera_blur_px``, 0.5: the camera model of EVALUATION.md)."""
    return camera_blur_px * float(np.sqrt(max(d * d - 1.0, 0.0)))


@dataclass(frozen=True)
class Level:
    """One level of the scale-space: the image at decimation ``d`` (float32, grey levels).

    ``image[y_d, x_d]`` is the full-resolution image blurred by ``blur`` px, sampled at
    ``x = d * x_d + (d - 1) / 2`` (same for y).
    """

    s: float  #: the scale this level serves (dimensionless, the paper's s)
    d: float  #: decimation factor (full-resolution px per level px)
    blur: float  #: blur already in ``image``, in full-resolution px
    image: np.ndarray  #: (H_d, W_d) float32

    def sigma_on_level(self, sigma_full: float) -> float:
        """Std, in level pixels, that brings the total blur to ``sigma_full`` full-res px."""
        rest = max(sigma_full * sigma_full - self.blur * self.blur, 0.0)
        return float(np.sqrt(rest)) / self.d

    def to_full(self, xy: np.ndarray) -> np.ndarray:
        """Level pixel coordinates (N, 2) -> full-resolution pixel coordinates (N, 2)."""
        return apply(resize_map(self.d), xy)

    def to_level(self, xy: np.ndarray) -> np.ndarray:
        """Full-resolution pixel coordinates (N, 2) -> level pixel coordinates (N, 2)."""
        return apply(resize_map(1.0 / self.d), xy)


def as_float_image(image: np.ndarray) -> np.ndarray:
    """A 2-D grey image as a contiguous float32 array (grey levels kept as they are)."""
    image = np.asarray(image)
    if image.ndim != 2:
        raise ValueError(f"expected a 2-D grey image, got an array of shape {image.shape}")
    return np.ascontiguousarray(image, dtype=np.float32)


def gaussian_blur(image: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur with std ``sigma`` px (identity for sigma <= 0.05), reflected borders."""
    if sigma <= 0.05:
        return image
    return cv2.GaussianBlur(image, (0, 0), sigmaX=sigma, sigmaY=sigma,
                            borderType=cv2.BORDER_REFLECT_101)


def resample(image: np.ndarray, factor: float) -> np.ndarray:
    """Sample ``image`` every ``factor`` px, centre-aligned (``x_src = f*x_dst + (f-1)/2``)."""
    if abs(factor - 1.0) < 1e-9:
        return image
    h, w = image.shape
    out_w = max(int(np.floor((w - 1 - (factor - 1) / 2) / factor)) + 1, 1)
    out_h = max(int(np.floor((h - 1 - (factor - 1) / 2) / factor)) + 1, 1)
    return cv2.warpAffine(image, resize_map(factor), (out_w, out_h),
                          flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                          borderMode=cv2.BORDER_REFLECT_101)


def decimation_for(s: float, sigma: float, min_level_sigma: float) -> float:
    """Largest decimation that keeps the derivation Gaussian at >= ``min_level_sigma`` level px."""
    return max(1.0, s * sigma / min_level_sigma)


def scale_space(image: np.ndarray, scales: Sequence[float], sigma: float = 1.0,
                min_level_sigma: float = 1.0, decimate: bool = True,
                camera_blur_px: float = 0.5) -> Iterator[Level]:
    """Yield one :class:`Level` per scale, in the order of ``scales`` (a cascade when increasing).

    Parameters
    ----------
    image : (H, W) array
        Grey image (grey levels, any real dtype).
    scales : sequence of float
        The paper's s values (>= 1 for a meaningful scale-space; 1 = the image itself).
    sigma : float
        The derivation std at s = 1, px (paper: 1).
    min_level_sigma : float
        Smallest derivation std, in level px, allowed when choosing the decimation.
    decimate : bool
        False computes every scale at full resolution (the paper, literally; for checks).
    camera_blur_px : float
        Blur each decimated copy carries, in its own px (:func:`antialias_sigma`).
    """
    base = as_float_image(image)
    current = Level(s=1.0, d=1.0, blur=0.0, image=base)
    for s in scales:
        d = decimation_for(float(s), sigma, min_level_sigma) if decimate else 1.0
        source = current if d >= current.d else Level(1.0, 1.0, 0.0, base)
        target_blur = antialias_sigma(d, camera_blur_px)
        extra = np.sqrt(max(target_blur ** 2 - source.blur ** 2, 0.0)) / source.d
        img = resample(gaussian_blur(source.image, extra), d / source.d)
        current = Level(s=float(s), d=d, blur=max(target_blur, source.blur), image=img)
        yield current
