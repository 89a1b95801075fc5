"""scalematch: match a low-resolution image against a high-resolution one with unknown zoom.

Implements Dufournaud, Schmid & Horaud, "Image Matching with Scale Adjustment", CVIU 93 (2004).
The pipeline, by module: ``stages/scalespace`` -> ``stages/detector`` -> ``stages/descriptors``
-> ``stages/mahalanobis`` -> ``stages/matcher`` -> ``stages/constraints`` ->
``stages/estimator`` -> ``stages/decision``, run by the ``search`` package for ``pipeline``;
then ``render``/``cli``. The research code (synthetic pairs, benchmark, studies) is
``scalematch.lab``, which this package never imports.

A scene and a copy shrunk 3 times and turned 20 degrees (``transform`` maps the finer image's
pixels to the coarser one's):

>>> import cv2, numpy as np
>>> from scalematch import match
>>> from scalematch.geometry import similarity_matrix
>>> noise = np.random.default_rng(0).uniform(0, 255, (240, 320)).astype(np.float32)
>>> scene = cv2.normalize(cv2.GaussianBlur(noise, (0, 0), 3), None, 0, 255, cv2.NORM_MINMAX)
>>> low = cv2.warpAffine(scene, similarity_matrix(1 / 3, 20.0, 30.0, 20.0), (160, 120),
...                      flags=cv2.INTER_AREA)
>>> r = match(low, scene)
>>> r.matched, round(r.resolution_ratio, 1), round(r.rotation_deg), r.transform.shape
(True, 3.0, 20, (2, 3))
>>> rng = np.random.default_rng(1)
>>> match(rng.normal(128, 3, (60, 80)), rng.normal(90, 3, (120, 160))).matched  # nothing to match
False
>>> match(np.full((60, 80), 128.0), scene)  # a constant image: not even a try
Traceback (most recent call last):
    ...
scalematch.imagefile.ImageError: the low image is constant (every pixel 128): there is nothing to match in it
"""

__version__ = "0.1.0"

#: The public names, each loaded from its module on first use (PEP 562), so that
#: ``import scalematch`` and the command line's start-up load only what a command needs
#: (``scalematch --help`` never loads the pipeline).
_EXPORTS = {
    "match": ".pipeline",
    "Config": ".config",
    "HarrisParams": ".stages.detector",
    "Keypoints": ".stages.detector",
    "PAPER_SCALES": ".stages.detector",
    "detect": ".stages.detector",
    "ImageError": ".imagefile",
    "ImageWarning": ".imageio",
    "read_grey": ".imageio",
    "MatchResult": ".result",
    "ScaleRow": ".result",
}

__all__ = list(_EXPORTS) + ["__version__"]


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'scalematch' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(_EXPORTS[name], __name__), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__():
    return sorted(set(globals()) | set(_EXPORTS))
