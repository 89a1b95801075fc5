"""Stages 2-3: sampled Gaussian derivative filters, the building block of Harris and the jet (docs/ALGORITHM.md steps 2-3).

``gaussian_derivative(image, sigma, ox, oy)`` is the derivative of order ``ox`` in x and ``oy`` in
y of the image smoothed by a Gaussian of std ``sigma`` px: the "L_{x..xy..y}" of the local jet
(Koenderink & van Doorn 1987). Kernels are sampled Gaussian derivatives, normalised so that they
are exact on polynomials of their own order (a ramp for order 1, x^2/2 for order 2, x^3/6 for 3).
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

#: Kernel half-width in stds: 4 sigma leaves < 1e-4 of a Gaussian's mass outside.
KERNEL_RADIUS_STDS = 4.0


@lru_cache(maxsize=256)
def _kernel(sigma: float, order: int) -> np.ndarray:
    radius = max(int(np.ceil(KERNEL_RADIUS_STDS * sigma + order)), 1)
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    g = np.exp(-0.5 * (x / sigma) ** 2)
    if order == 0:
        k = g / g.sum()
    elif order == 1:
        k = x * g
        k /= np.sum(k * x)
    elif order == 2:
        k = (x * x - sigma * sigma) * g
        k = k - g * (k.sum() / g.sum())  # zero response to constants
        k /= np.sum(k * x * x / 2.0)
    elif order == 3:
        k = (x ** 3 - 3 * x * sigma * sigma) * g
        k = k - x * g * (np.sum(k * x) / np.sum(x * g * x))  # zero response to ramps
        k /= np.sum(k * x ** 3 / 6.0)
    else:
        raise ValueError(f"derivative order {order} not supported (0..3)")
    # cv2.sepFilter2D correlates: out(x) = sum_i k[i] f(x + i). The normalisation above makes
    # sum_i k[i] i^n / n! = 1 for n = order, so correlation returns the derivative as it is.
    return k.astype(np.float32)


def gaussian_derivative(image: np.ndarray, sigma: float, ox: int = 0, oy: int = 0) -> np.ndarray:
    """d^(ox+oy) (G_sigma * image) / dx^ox dy^oy, same shape, float32, reflected borders."""
    kx = _kernel(round(float(sigma), 6), ox)
    ky = _kernel(round(float(sigma), 6), oy)
    return cv2.sepFilter2D(image, cv2.CV_32F, kx, ky, borderType=cv2.BORDER_REFLECT_101)
