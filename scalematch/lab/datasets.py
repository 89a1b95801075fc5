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
from typing import Iterable, List, Optional, Sequence, Tuple, Union

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


#: The command line's exit code of bad input or usage (``scalematch.exits.EXIT_BAD_INPUT``): a
#: lab command whose data is not where it looked was not told where the data is; not 1, which
#: the command line keeps for "no reliable match" (and the lab's gates for a failed gate)
EXIT_NO_DATA = 2
#: How to point a lab command with a ``--shared`` option at the shared folder
POINT_WITH_OPTION = f"point at the shared folder with --shared DIR or {SHARED_ENV}=DIR"


class SharedDataMissing(click.ClickException):
    """The shared data a lab command needs is not where it looked: ``Error: ...`` on stderr,
    saying where it looked and how to point at the folder, and exit 2 (``EXIT_NO_DATA``)."""

    exit_code = EXIT_NO_DATA


def shared_place(env: Optional[dict] = None) -> Tuple[Path, str]:
    """Where the shared folder is looked for, and what says so: the folder of
    ``$SCALEMATCH_SHARED`` when it is set, else ``<repo root>/../shared``."""
    env = os.environ if env is None else env
    value = env.get(SHARED_ENV)
    if value:
        return Path(value).expanduser(), f"from ${SHARED_ENV}"
    return (Path(__file__).resolve().parents[3] / "shared",
            f"../shared beside the repository, as ${SHARED_ENV} is not set")


def find_shared(env: Optional[dict] = None) -> Optional[Path]:
    """The shared folder: ``$SCALEMATCH_SHARED``, else ``<repo root>/../shared``; None if absent."""
    place, _ = shared_place(env)
    return place if place.is_dir() else None


def require_shared(shared: Optional[PathLike] = None, subdir: PathLike = "data/photos",
                   point: str = POINT_WITH_OPTION) -> Path:
    """The shared folder a lab command reads: ``shared`` (its ``--shared``), else where
    :func:`find_shared` looks; ``SharedDataMissing`` when its ``subdir`` (the part the command
    needs) is not there, saying where it looked and how to point at the folder (``point``)."""
    place, why = (Path(shared), "from --shared") if shared is not None else shared_place()
    if (place / subdir).is_dir():
        return place
    raise SharedDataMissing(f"the shared data is missing: this command reads {place / subdir}, "
                            f"which is not there ({why}); {point}")


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


def other_scene(names: Sequence[str], start: int, avoid: Iterable[str]) -> int:
    """The index of the first name after ``start`` (cyclically) whose scene
    (:func:`scene_of`) is none of the scenes of ``avoid`` (names); ``start + 1`` when every
    photo is of those scenes. An occluder cut from it shows neither image's scene: the next
    photo of the list is often another shot of the same place (brighton_DJI_0020 and 0026),
    whose patch the coarser image does hold.

    >>> other_scene(["a_1.jpg", "a_2.jpg", "b_1.jpg", "c_1.jpg"], 0, ["a_1.jpg", "b_1.jpg"])
    3
    """
    scenes = {scene_of(n) for n in avoid}
    for k in range(1, len(names)):
        if scene_of(names[(start + k) % len(names)]) not in scenes:
            return (start + k) % len(names)
    return (start + 1) % len(names)


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

    Raises ``SharedDataMissing`` when there is no photo.
    """
    point = f"give image paths, or point at the shared folder with {SHARED_ENV}=DIR"
    if images:
        paths = [Path(p) for p in images]
    else:
        paths = list_photos(require_shared(point=point))
    if not paths:
        place, why = shared_place()
        raise SharedDataMissing(f"no photos in {place / 'data' / 'photos'} ({why}); {point}")
    if n_photos is not None:
        paths = paths[:n_photos]
    total = len(paths)
    counter = iter(range(1, total + 1))
    progress = None if silent else (
        lambda name: click.echo(f"[{next(counter)}/{total}] {name}", err=True))
    return paths, progress
