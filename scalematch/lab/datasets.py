"""Where the evaluation data lives and how to read it (the ``shared`` folder, EVALUATION.md).

The shared folder holds ``data/photos`` (large real photos to cut synthetic zoom pairs from) and
``data/oxford/boat`` (a real zoom sequence with homography ground truth). It is found from the
environment variable ``SCALEMATCH_SHARED``, else ``<repo root>/../shared``; nothing is ever
copied from it into the repository.

Photo file names start with a scene prefix ending at the first ``_`` (``sceaux_100_7100.JPG``):
two photos with the same prefix may show the same scene and are never used as an unrelated pair.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import List, Optional, Tuple, Union

import click
import numpy as np

from ..imageio import read_grey

#: Environment variable naming the shared folder.
SHARED_ENV = "SCALEMATCH_SHARED"
#: Photo file extensions listed by ``list_photos`` (compared lower-case).
PHOTO_EXTENSIONS = (".jpg", ".jpeg", ".png", ".tif", ".tiff")
#: The boat sequence: high = img1, low = imgN, truth H1toNp (data/oxford/SOURCES.md).
BOAT_LOW_INDICES = (2, 3, 4, 5, 6)

PathLike = Union[str, Path]


def find_shared(env: Optional[dict] = None) -> Optional[Path]:
    """The shared folder: ``$SCALEMATCH_SHARED``, else ``<repo root>/../shared``; None if absent."""
    env = os.environ if env is None else env
    value = env.get(SHARED_ENV)
    if value:
        p = Path(value).expanduser()
        return p if p.is_dir() else None
    p = Path(__file__).resolve().parents[3] / "shared"
    return p if p.is_dir() else None


def shared_subfolder(subdir: PathLike, shared: Optional[PathLike] = None) -> Optional[Path]:
    """``<shared>/<subdir>`` (``shared`` default: :func:`find_shared`); None if absent."""
    shared = find_shared() if shared is None else Path(shared)
    if shared is None:
        return None
    folder = Path(shared) / subdir
    return folder if folder.is_dir() else None


def list_photos(shared: PathLike) -> List[Path]:
    """The photos of ``shared/data/photos``, sorted by file name (empty when there are none)."""
    folder = Path(shared) / "data" / "photos"
    if not folder.is_dir():
        return []
    return sorted((p for p in folder.iterdir()
                   if p.is_file() and p.suffix.lower() in PHOTO_EXTENSIONS), key=lambda p: p.name)


#: The ``--shared`` option of the lab's commands on real pairs (a decorator): the shared folder
shared_option = click.option(
    "--shared", type=click.Path(file_okay=False, path_type=Path), default=None,
    help="The shared folder (default: ../shared beside the repo, or $SCALEMATCH_SHARED).")


def scene_of(name: Union[str, Path]) -> str:
    """The scene prefix of a photo file name: what comes before the first ``_``."""
    stem = Path(str(name)).name
    return stem.split("_", 1)[0]


def load_photo(path: PathLike) -> np.ndarray:
    """A photo as (H, W) float32 grey levels, EXIF orientation applied (BT.601 luma)."""
    return read_grey(path)


def boat_pairs(shared: PathLike) -> List[Tuple[np.ndarray, np.ndarray, np.ndarray, str]]:
    """The boat zoom pairs 1->2 .. 1->6 as (low, high, H, name).

    ``low`` = imgN and ``high`` = img1, (H, W) float32 grey; ``H`` (3x3 float64) maps an img1
    pixel to an imgN pixel (high px -> low px); ``name`` is ``"boat 1->N"``. Empty when the
    folder is absent.
    """
    folder = Path(shared) / "data" / "oxford" / "boat"
    if not (folder / "img1.png").is_file():
        return []
    high = read_grey(folder / "img1.png")
    out = []
    for n in BOAT_LOW_INDICES:
        img, hfile = folder / f"img{n}.png", folder / f"H1to{n}p"
        if not (img.is_file() and hfile.is_file()):
            continue
        h = np.loadtxt(hfile, dtype=np.float64).reshape(3, 3)
        out.append((read_grey(img), high, h / h[2, 2], f"boat 1->{n}"))
    return out


def study_photos(images, n_photos: Optional[int], silent: bool):
    """(paths, progress) of a study command: the images given, else the shared photos, the
    first ``n_photos`` of them; ``progress(name)`` prints "[k/N] name" (None when silent).

    Raises ``click.ClickException`` when there is no photo.
    """
    if images:
        paths = [Path(p) for p in images]
    else:
        shared = find_shared()
        paths = list_photos(shared) if shared is not None else []
    if not paths:
        raise click.ClickException("no photos: give image paths, or set SCALEMATCH_SHARED to a "
                                   "folder with data/photos")
    if n_photos is not None:
        paths = paths[:n_photos]
    total = len(paths)
    counter = iter(range(1, total + 1))
    progress = None if silent else (
        lambda name: click.echo(f"[{next(counter)}/{total}] {name}", err=True))
    return paths, progress
