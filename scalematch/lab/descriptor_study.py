"""How distinctive are the descriptors? Nearest-neighbour identification under a known change.

For each photo, a crop and a changed copy *at the same resolution* (so the descriptors alone are
measured, not the scale selection): the copy is the crop rotated about its centre by a random
angle, re-lit and noised. Points are detected in both (the library's Harris detector at s = 1,
``HarrisParams`` with the absolute threshold); a point of the crop is *identified* when its
nearest neighbour in descriptor space, among **all** the points of the copy, is its true partner
(the copy's point nearest its mapped position, within ``match_px``). Protocol, all numbers
``StudyParams`` fields:

* crop = ``crop_w`` x ``crop_h`` of the photo: of ``crop_candidates`` random positions (seeded
  from ``seed`` and the photo's file name) the most textured
  (:func:`scalematch.lab.repeatability.choose_crop`; a crop of plain sky measures nothing);
* copy = ``cv2.warpAffine`` (INTER_CUBIC, reflected border) rotating the crop about its centre by
  theta uniform in [-180, 180), then ``gain * I + offset`` (gain uniform in ``gain``, offset in
  ``offset``), Gaussian noise of std ``noise_std``, rounded and clipped to 8 bits;
* points of the crop count when they and their mapped position lie at least ``margin_px`` inside
  their image (the reflected corners of the copy hold no true partner);
* descriptors: (a) jets (:func:`~scalematch.stages.descriptors.describe_jets`, default ``JetParams``)
  whitened by the shipped Lambda (Mahalanobis distance); (b) the same jets with plain Euclidean
  distance on the raw invariants; (c) the default oriented-gradient descriptor
  (:func:`~scalematch.stages.descriptors.describe_gradients`, Euclidean; a point with several dominant
  orientations has several rows and its distance to a copy point is the smallest over the row
  pairs); (d) = (a) counted only over the points that have a true partner (the descriptor's
  share of the failures, without the detector's); (e) = (c) likewise; (f) jets Mahalanobis on
  the five invariants v2, v3, v4, v6, v8 only (the 5x5 block of Lambda), a diagnostic.

Run it: ``python -m scalematch.lab.descriptor_study --photos 38 --out docs/results/DESCRIPTORS.md``.
"""

from __future__ import annotations

import math
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, List, Optional, Sequence, Tuple, Union

import click
import cv2
import numpy as np

from ..geometry import apply, similarity_matrix
from ..stages.descriptors import GradientParams, JetParams, describe_gradients, describe_jets
from ..stages.detector import HarrisParams, detect_one
from ..stages.mahalanobis import load_covariance, whiten
from ..stages.scalespace import Level
from .datasets import load_photo, study_photos
from .repeatability import choose_crop

PathLike = Union[str, Path]

#: Columns of the table: key, heading.
COLUMNS = (
    ("jets_mahalanobis", "(a) jets Mahal."),
    ("jets_euclidean", "(b) jets Eucl."),
    ("gradients", "(c) gradients"),
    ("jets_mahalanobis_partnered", "(d) jets Mahal., partnered"),
    ("gradients_partnered", "(e) gradients, partnered"),
    ("jets_five", "(f) 5 jets Mahal."),
)
#: The invariants (columns of the 7-vector) that (f) keeps: v2, v3, v4, v6, v8.
FIVE = (0, 1, 2, 4, 6)


@dataclass(frozen=True)
class StudyParams:
    crop_w: int = 800  #: crop width, px
    crop_h: int = 600  #: crop height, px
    crop_candidates: int = 6  #: random crop positions tried; the most textured is kept
    gain: Tuple[float, float] = (0.7, 1.3)  #: grey-level gain range (uniform)
    offset: Tuple[float, float] = (-20.0, 20.0)  #: grey-level offset range (uniform)
    noise_std: float = 3.0  #: Gaussian noise std, grey levels
    match_px: float = 1.5  #: true partner: the copy point within this distance of the mapped one
    margin_px: float = 20.0  #: points and mapped points kept this far inside their image, px


@dataclass(frozen=True)
class PhotoResult:
    name: str
    angle_deg: float
    gain: float
    offset: float
    n_points: int  #: crop points counted (inside, mapped inside)
    n_copy: int  #: all points of the copy (the candidates of every nearest-neighbour search)
    partnered: float  #: fraction of the counted points that have a true partner
    jets_mahalanobis: float
    jets_euclidean: float
    gradients: float
    jets_mahalanobis_partnered: float
    gradients_partnered: float
    jets_five: float


def photo_rng(seed: int, name: str) -> np.random.Generator:
    """A generator that depends on the seed and the photo's file name only (not on the list)."""
    return np.random.default_rng([int(seed), zlib.crc32(name.encode("utf-8"))])


def changed_copy(image: np.ndarray, angle_deg: float, gain: float, offset: float,
                 noise_std: float, rng: np.random.Generator) -> Tuple[np.ndarray, np.ndarray]:
    """(copy, A): ``image`` turned about its centre, re-lit, noised, 8-bit; A: image -> copy."""
    img = np.asarray(image, np.float32)
    h, w = img.shape
    c = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    a = similarity_matrix(1.0, angle_deg)
    a[:, 2] = c - a[:, :2] @ c
    out = cv2.warpAffine(img, a, (w, h), flags=cv2.INTER_CUBIC,
                         borderMode=cv2.BORDER_REFLECT_101).astype(np.float64)
    out = gain * out + offset + rng.normal(0.0, noise_std, out.shape)
    return np.clip(np.rint(out), 0, 255).astype(np.float32), a


def true_partners(mapped: np.ndarray, copy_xy: np.ndarray, match_px: float) -> np.ndarray:
    """Per mapped point (N, 2): the row of the nearest copy point within ``match_px``, else -1."""
    if mapped.shape[0] == 0 or copy_xy.shape[0] == 0:
        return np.full(mapped.shape[0], -1, int)
    d = np.linalg.norm(mapped[:, None, :] - copy_xy[None, :, :], axis=2)
    j = d.argmin(axis=1)
    return np.where(d[np.arange(d.shape[0]), j] <= match_px, j, -1)


def nearest_points(a: np.ndarray, b: np.ndarray, a_point: Optional[np.ndarray] = None,
                   b_point: Optional[np.ndarray] = None, n_a: Optional[int] = None) -> np.ndarray:
    """For each point of ``a``, the point of ``b`` whose descriptor is nearest (Euclidean).

    ``a`` (Na, D) and ``b`` (Nb, D) are descriptor rows; ``a_point`` / ``b_point`` give the point
    each row belongs to (identity when None) and ``n_a`` the number of points of ``a``. A point
    with no row gets -1; a point's distance to a copy point is the smallest over their rows.
    """
    a_point = np.arange(a.shape[0]) if a_point is None else np.asarray(a_point)
    b_point = np.arange(b.shape[0]) if b_point is None else np.asarray(b_point)
    n_a = a.shape[0] if n_a is None else n_a
    out = np.full(n_a, -1, int)
    if a.shape[0] == 0 or b.shape[0] == 0:
        return out
    a64, b64 = np.asarray(a, np.float64), np.asarray(b, np.float64)
    d2 = (np.einsum("ij,ij->i", a64, a64)[:, None] + np.einsum("ij,ij->i", b64, b64)[None, :]
          - 2.0 * a64 @ b64.T)
    row_best = d2.argmin(axis=1)
    row_dist = d2[np.arange(d2.shape[0]), row_best]
    best = np.full(n_a, np.inf)
    np.minimum.at(best, a_point, row_dist)  # smallest over each point's rows
    hit = row_dist <= best[a_point]
    out[a_point[hit]] = b_point[row_best[hit]]
    return out


def _fraction(correct: np.ndarray) -> float:
    return float(np.mean(correct)) if correct.size else float("nan")


def measure_photo(photo: np.ndarray, name: str, seed: int,
                  params: StudyParams = StudyParams(),
                  whitening: Optional[np.ndarray] = None) -> PhotoResult:
    """The identification fractions of every descriptor on one photo (module docstring)."""
    rng = photo_rng(seed, name)
    x0, y0, w, h = choose_crop(photo, (params.crop_w, params.crop_h), 0, params.crop_candidates,
                               1.0, rng)
    crop = np.ascontiguousarray(photo[y0:y0 + h, x0:x0 + w], dtype=np.float32)
    angle = float(rng.uniform(-180.0, 180.0))
    gain = float(rng.uniform(*params.gain))
    offset = float(rng.uniform(*params.offset))
    copy, a = changed_copy(crop, angle, gain, offset, params.noise_std, rng)

    harris = HarrisParams(contrast_relative=False, min_points=0)  # the absolute threshold, as measured
    k0 = detect_one(crop, 1.0, harris).xy
    k1 = detect_one(copy, 1.0, harris).xy
    mapped = apply(a, k0)
    m = params.margin_px
    lim = np.array([w - 1 - m, h - 1 - m])
    keep = np.all((k0 >= m) & (k0 <= lim) & (mapped >= m) & (mapped <= lim), axis=1)
    p0, q0 = k0[keep], mapped[keep]
    n = p0.shape[0]
    truth = true_partners(q0, k1, params.match_px)
    has = truth >= 0

    l0, l1 = Level(1.0, 1.0, 0.0, crop), Level(1.0, 1.0, 0.0, copy)
    j0 = describe_jets(l0, p0, harris.sigma_tilde, JetParams())
    j1 = describe_jets(l1, k1, harris.sigma_tilde, JetParams())
    if whitening is None:
        whitening = load_covariance().whitening()
    cov = np.linalg.inv(whitening @ whitening)  # Lambda back from W = Lambda^-1/2
    w5 = _whitening(cov[np.ix_(FIVE, FIVE)])
    nn_maha = nearest_points(whiten(j0, whitening), whiten(j1, whitening))
    nn_eucl = nearest_points(j0, j1)
    nn_five = nearest_points(whiten(j0[:, FIVE], w5), whiten(j1[:, FIVE], w5))
    g0 = describe_gradients(l0, p0, GradientParams())
    g1 = describe_gradients(l1, k1, GradientParams())
    nn_grad = nearest_points(g0.desc, g1.desc, g0.index, g1.index, n)

    def ok(nn):
        return has & (nn == truth)

    return PhotoResult(
        name=name, angle_deg=angle, gain=gain, offset=offset, n_points=int(n),
        n_copy=int(k1.shape[0]), partnered=_fraction(has),
        jets_mahalanobis=_fraction(ok(nn_maha)), jets_euclidean=_fraction(ok(nn_eucl)),
        gradients=_fraction(ok(nn_grad)), jets_mahalanobis_partnered=_fraction(ok(nn_maha)[has]),
        gradients_partnered=_fraction(ok(nn_grad)[has]), jets_five=_fraction(ok(nn_five)))


def _whitening(cov: np.ndarray) -> np.ndarray:
    w, v = np.linalg.eigh(cov)
    return (v / np.sqrt(np.maximum(w, 1e-12 * w.max()))) @ v.T


def run_study(paths: Sequence[PathLike], seed: int = 0, params: StudyParams = StudyParams(),
              progress: Optional[Callable[[str], None]] = None
              ) -> Tuple[List[PhotoResult], List[Tuple[str, str]]]:
    """(results, skipped) over the photos; ``skipped`` holds (name, reason)."""
    whitening = load_covariance().whitening()
    results, skipped = [], []
    for p in paths:
        p = Path(p)
        if progress is not None:
            progress(p.name)
        try:
            results.append(measure_photo(load_photo(p), p.name, seed, params, whitening))
        except (OSError, ValueError) as err:
            skipped.append((p.name, str(err)))
    return results, skipped


# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------

def _pct(v: float) -> str:
    return "-" if not math.isfinite(v) else f"{100 * v:.1f}"


def means(results: Sequence[PhotoResult]) -> dict:
    """Mean over photos of each fraction (and of ``partnered``)."""
    keys = ["partnered"] + [k for k, _ in COLUMNS]
    return {k: float(np.nanmean([getattr(r, k) for r in results])) if results else float("nan")
            for k in keys}


def format_table(results: Sequence[PhotoResult]) -> str:
    """A markdown table, one row per photo and a final row of means (percent)."""
    head = ["photo", "angle", "gain", "offset", "points", "partnered"] + [h for _, h in COLUMNS]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in results:
        cells = [r.name, f"{r.angle_deg:.1f}", f"{r.gain:.2f}", f"{r.offset:+.1f}",
                 str(r.n_points), _pct(r.partnered)] + [_pct(getattr(r, k)) for k, _ in COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    mu = means(results)
    cells = [f"**mean of {len(results)}**", "", "", "", "", _pct(mu["partnered"])] + [
        f"**{_pct(mu[k])}**" for k, _ in COLUMNS]
    lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def existing_reading(path: PathLike) -> str:
    """The hand-written "## Reading" section of an existing report (kept across re-runs)."""
    p = Path(path)
    if not p.is_file():
        return "(to be written: what the table says)"
    text = p.read_text()
    mark = "\n## Reading\n"
    return text.split(mark, 1)[1].strip() if mark in text else "(to be written)"


def write_doc(results: Sequence[PhotoResult], path: PathLike, command: str, seed: int,
              params: StudyParams, seconds: float, reading: str = "") -> Path:
    """docs/results/DESCRIPTORS.md: command, protocol, table, reading (``reading`` is markdown)."""
    mu = means(results)
    prov = load_covariance().provenance
    recipe = prov.get("recipe", {})
    text = f"""# Descriptors: nearest-neighbour identification under rotation and lighting

Written by `scalematch/lab/descriptor_study.py`. Every number on this page comes from this command,
run from the repository root with `../shared` present ({len(results)} photos, seed {seed},
{seconds:.0f} s):

```
{command}
```

## The two descriptors

* **Local-jet invariants** (the paper, `mode="paper"`): the 7-vector of Schmid & Mohr's
  differential invariants v2..v8 up to third order, each divided by the matching power of the
  gradient magnitude (grey-level gain) and multiplied by the matching power of the jet's std
  (dimensionless). The exact definition is the module docstring of `scalematch/stages/descriptors.py`.
  They are compared by the Mahalanobis distance with the covariance Lambda of
  `scalematch/data/jet_covariance.json` (whitening by Lambda^-1/2, `scalematch/stages/mahalanobis.py`).
* **Oriented gradient histograms** (the default): a dominant orientation and 4x4x8 histograms
  in the turned window, RootSIFT-normalised (unit vectors), Euclidean distance.

**How Lambda was made** (the `provenance` block of `scalematch/data/jet_covariance.json`): method
"{prov.get("method", "?")}", seed {prov.get("seed", "?")}, {len(prov.get("photos", []))} photos
of `../shared/data/photos`. From each, {recipe.get("crops_per_photo", "?")} random crops of
{recipe.get("crop", "?")} px; each crop is rotated by a random angle, scaled by up to
+-{recipe.get("scale_error", "?")}, re-lit (gain in {recipe.get("gain", "?")}, offset in
{recipe.get("offset", "?")}) and noised (std up to {recipe.get("noise_std", "?")}); the points
re-detected within {recipe.get("match_px", "?")} px give descriptor differences, and Lambda is
their covariance after dropping the largest {prov.get("trimmed_fraction", "?")} (in a first
covariance's metric): {load_covariance().samples} differences.
`scalematch lab covariance photos/*.jpg -o my_covariance.json` re-estimates it
(`lab/covariance.estimate_covariance`); `--set covariance_path=my_covariance.json` uses it.

## Protocol

For each photo: a {params.crop_w}x{params.crop_h} crop (of {params.crop_candidates} random
positions, the most textured) and a copy at the same resolution, rotated about its centre by a
random angle (uniform in [-180, 180), `cv2.warpAffine`, INTER_CUBIC, reflected border), re-lit
(gain uniform in [{params.gain[0]:g}, {params.gain[1]:g}], offset in [{params.offset[0]:g},
{params.offset[1]:g}]), noised (std {params.noise_std:g} grey levels), rounded to 8 bits. The
crop, angle, gain, offset and noise are drawn from the seed and the photo's file name.

Harris points of both images at s = 1 (`HarrisParams`, absolute threshold). A crop point counts
when it and its mapped position are at least {params.margin_px:g} px inside their image; its **true
partner** is the copy point nearest its mapped position, if within {params.match_px:g} px. A
point is **identified** when its nearest neighbour in descriptor space, among *all* the points
of the copy, is its true partner. Columns (percent of the counted points):

* **partnered**: points with a true partner (the detector's repeatability under the change);
* **(a)** jets, Mahalanobis distance (whitened by the shipped Lambda);
* **(b)** jets, plain Euclidean distance on the raw invariants;
* **(c)** gradient histograms, Euclidean (a point with two dominant orientations has two rows;
  its distance to a copy point is the smallest over the row pairs);
* **(d)** = (a) and **(e)** = (c), counted over the partnered points only (the descriptor's
  failures without the detector's);
* **(f)** jets, Mahalanobis on v2, v3, v4, v6, v8 only (the 5x5 block of Lambda): a diagnostic,
  see the reading.

## Results (percent)

Means over {len(results)} photos: partnered {_pct(mu["partnered"])}; (a)
{_pct(mu["jets_mahalanobis"])}, (b) {_pct(mu["jets_euclidean"])}, (c) {_pct(mu["gradients"])},
(d) {_pct(mu["jets_mahalanobis_partnered"])}, (e) {_pct(mu["gradients_partnered"])}, (f)
{_pct(mu["jets_five"])}.

{format_table(results)}

## Reading

{reading}
"""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------

@click.command("descriptor-study")
@click.argument("images", nargs=-1, type=click.Path(exists=True, dir_okay=False))
@click.option("--photos", "n_photos", type=click.IntRange(min=1), default=None,
              help="Use only the first N photos (sorted by name).")
@click.option("--seed", type=int, default=0, show_default=True,
              help="The one seed (crops, angles, gains, offsets, noise).")
@click.option("--out", type=click.Path(dir_okay=False), default=None,
              help="Write the report (markdown) here, e.g. docs/results/DESCRIPTORS.md.")
@click.option("--silent", is_flag=True, help="No progress messages.")
def descriptor_study_command(images, n_photos, seed, out, silent):
    """Nearest-neighbour identification of jets and gradient descriptors under rotation + lighting.

    IMAGES are photos (default: the photos of the shared folder, $SCALEMATCH_SHARED or
    <repo>/../shared). Prints the table; --out writes it with the protocol as markdown (the
    "## Reading" section of an existing --out file is kept: it is written by hand).

    Example: scalematch lab descriptor-study --photos 38 --out docs/results/DESCRIPTORS.md
    """
    paths, progress = study_photos(images, n_photos, silent)
    params = StudyParams()
    t0 = time.perf_counter()
    results, skipped = run_study(paths, seed, params, progress)
    seconds = time.perf_counter() - t0
    for name, why in skipped:
        click.echo(f"skipped {name}: {why}", err=True)
    if not results:
        raise click.ClickException("no photo could be used (see the messages above)")
    click.echo(format_table(results))
    if out:
        parts = ["python -m scalematch.lab.descriptor_study"]
        if images:
            parts += [str(p) for p in images]
        if n_photos is not None:
            parts += ["--photos", str(n_photos)]
        if seed != 0:
            parts += ["--seed", str(seed)]
        parts += ["--out", str(out)]
        write_doc(results, out, " ".join(parts), seed, params, seconds, existing_reading(out))
        click.echo(f"wrote {out}", err=True)


if __name__ == "__main__":
    descriptor_study_command()
