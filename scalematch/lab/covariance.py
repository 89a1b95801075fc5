"""Lab: estimate the jet covariance Lambda by tracking points through known synthetic changes.

The product only loads Lambda (:mod:`scalematch.stages.mahalanobis`, docs/ALGORITHM.md step 4); this
module makes it. Schmid & Mohr estimated it by tracking points through image sequences; here
points of real photos are tracked through known synthetic changes (rotation, a small scale
error, noise, gain and offset). ``scalematch lab covariance`` re-estimates it from a user's own
photos.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Optional, Sequence

import numpy as np

from ..geometry import apply, similarity_matrix
from ..stages.descriptors import JET_DIM, JetParams, describe_jets
from ..stages.detector import HarrisParams, detect_on_level
from ..stages.mahalanobis import Covariance, save_covariance
from ..stages.scalespace import Level

#: The detector the packaged covariance was estimated with: the absolute threshold (the product's
#: detector, ``HarrisParams()``, follows the image's contrast)
ABSOLUTE = HarrisParams(contrast_relative=False, min_points=0)


@dataclass(frozen=True)
class CovarianceRecipe:
    """The synthetic changes points are tracked through (docs/ALGORITHM.md step 4)."""

    crop: int = 512  #: side of the square crop taken from each photo, px
    crops_per_photo: int = 4
    scale_error: float = 0.1  #: relative scale change, uniform in [-x, x] (scales are discrete)
    gain: Sequence[float] = (0.7, 1.3)  #: grey-level gain range
    offset: Sequence[float] = (-20.0, 20.0)  #: grey-level offset range
    noise_std: float = 3.0  #: max Gaussian noise std, grey levels
    match_px: float = 1.5  #: a point is tracked when re-detected within this distance
    trim: float = 0.05  #: fraction of the largest differences dropped (robust estimate)


def tracked_differences(image: np.ndarray, rng: np.random.Generator,
                        recipe: CovarianceRecipe = CovarianceRecipe(),
                        harris: HarrisParams = ABSOLUTE, jets: JetParams = JetParams()
                        ) -> np.ndarray:
    """Descriptor differences (N, D) of points re-detected after one random synthetic change."""
    import cv2

    img = np.asarray(image, np.float32)
    scale = 1.0 + rng.uniform(-recipe.scale_error, recipe.scale_error)
    angle = rng.uniform(-180.0, 180.0)
    h, w = img.shape
    c = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    a = similarity_matrix(scale, angle)
    a[:, 2] = c - a[:, :2] @ c
    warped = cv2.warpAffine(img, a, (w, h), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT_101)
    warped = warped * rng.uniform(*recipe.gain) + rng.uniform(*recipe.offset)
    warped = warped + rng.normal(0.0, rng.uniform(0, recipe.noise_std), warped.shape)
    warped = np.clip(np.rint(warped), 0, 255).astype(np.float32)
    l0 = Level(1.0, 1.0, 0.0, img)
    l1 = Level(1.0, 1.0, 0.0, warped)
    k0 = detect_on_level(l0, harris)
    k1 = detect_on_level(l1, harris)
    if len(k0) == 0 or len(k1) == 0:
        return np.zeros((0, JET_DIM))
    mapped = apply(a, k0.xy)
    margin = 16
    inside = np.all((mapped >= margin) & (mapped <= np.array([w, h]) - 1 - margin), axis=1)
    d = np.linalg.norm(mapped[inside, None, :] - k1.xy[None, :, :], axis=2)
    if d.size == 0:
        return np.zeros((0, JET_DIM))
    nearest = d.argmin(axis=1)
    ok = d[np.arange(d.shape[0]), nearest] <= recipe.match_px
    src = k0.xy[inside][ok]
    dst = k1.xy[nearest[ok]]
    v0 = describe_jets(l0, src, harris.sigma_tilde, jets)
    # the same physical point seen at a scale off by `scale`: its jet scale follows
    v1 = describe_jets(l1, dst, harris.sigma_tilde, jets)
    return (v1 - v0).astype(np.float64)


def estimate_covariance(images: Iterable[np.ndarray], seed: int = 0,
                        recipe: CovarianceRecipe = CovarianceRecipe(),
                        harris: HarrisParams = ABSOLUTE, jets: JetParams = JetParams(),
                        provenance: Optional[dict] = None) -> Covariance:
    """Estimate Lambda from grey photos by tracking points through random synthetic changes."""
    rng = np.random.default_rng(seed)
    diffs = []
    for img in images:
        img = np.asarray(img, np.float32)
        h, w = img.shape
        for _ in range(recipe.crops_per_photo):
            cs = min(recipe.crop, h, w)
            y = int(rng.integers(0, h - cs + 1))
            x = int(rng.integers(0, w - cs + 1))
            diffs.append(tracked_differences(img[y:y + cs, x:x + cs], rng, recipe, harris, jets))
    d = np.concatenate(diffs) if diffs else np.zeros((0, JET_DIM))
    d = d[np.all(np.isfinite(d), axis=1)]
    if d.shape[0] < 10 * JET_DIM:
        raise ValueError(f"only {d.shape[0]} tracked points: need more or more textured photos")
    # robust: drop the largest differences (in a first covariance's metric), then re-estimate
    c0 = np.cov(d, rowvar=False)
    m0 = np.sqrt(np.einsum("ni,ij,nj->n", d, np.linalg.pinv(c0), d))
    keep = m0 <= np.quantile(m0, 1.0 - recipe.trim)
    d = d[keep]
    cov = np.cov(d, rowvar=False)
    prov = dict(provenance or {})
    prov.update({"seed": seed, "recipe": {k: (list(v) if isinstance(v, tuple) else v)
                                          for k, v in recipe.__dict__.items()},
                 "trimmed_fraction": recipe.trim, "method": "tracked synthetic changes"})
    return Covariance(matrix=cov, mean=d.mean(axis=0), samples=int(d.shape[0]), provenance=prov)


# ------------------------------------------------------------------------------ command line


def _covariance_command():
    import click

    @click.command("covariance")
    @click.argument("photos", nargs=-1, type=click.Path(exists=True, dir_okay=False))
    @click.option("-o", "--output", type=click.Path(dir_okay=False), required=True,
                  help="Where to write the covariance (JSON).")
    @click.option("--seed", type=int, default=0, show_default=True)
    @click.option("--crops", type=int, default=CovarianceRecipe.crops_per_photo, show_default=True,
                  help="Random crops tracked per photo.")
    def covariance_command(photos, output, seed, crops):
        """Re-estimate the jet covariance Lambda from your own photos.

        Points of random crops are tracked through known synthetic changes (rotation, a small
        scale error, gain, offset, noise); the covariance of their descriptor differences is
        Lambda. Use the result with `scalematch --mode paper --set covariance_path=FILE`.

        \b
        Example:
          scalematch lab covariance photos/*.jpg -o my_covariance.json
        """
        from ..imagefile import ImageError
        from ..imageio import read_grey

        if not photos:
            raise click.UsageError("give at least one photo")
        try:
            images = [read_grey(p) for p in photos]
            cov = estimate_covariance(images, seed=seed,
                                      recipe=CovarianceRecipe(crops_per_photo=crops),
                                      provenance={"photos": [Path(p).name for p in photos]})
        except (ImageError, ValueError) as exc:
            raise click.ClickException(str(exc)) from exc
        save_covariance(cov, Path(output))
        click.echo(f"wrote {output}: {cov.samples} tracked points from {len(photos)} photos",
                   err=True)

    return covariance_command


covariance_command = _covariance_command()
