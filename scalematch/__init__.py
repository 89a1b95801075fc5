"""scalematch: match a low-resolution image against a high-resolution one with unknown zoom.

Implements Dufournaud, Schmid & Horaud, "Image Matching with Scale Adjustment", CVIU 93 (2004).
The pipeline, by module: ``scalespace`` -> ``detector`` -> descriptors -> matching ->
constraints -> estimation -> ``pipeline`` (scale selection and decision) -> ``render``/``cli``.
"""

from .config import Config
from .detector import HarrisParams, Keypoints, PAPER_SCALES, detect
from .imageio import ImageError, read_grey
from .result import MatchResult, ScaleRow

__version__ = "0.1.0"

__all__ = ["Config", "HarrisParams", "Keypoints", "PAPER_SCALES", "detect", "ImageError",
           "read_grey", "MatchResult", "ScaleRow", "__version__"]
