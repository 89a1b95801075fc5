"""The files a command writes: checked before the work (their folders made and writable,
never an input, nor one another), written after it (the JSON, an error's record too, the
pictures of ``-o``); a file that cannot be written is exit 2."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any, Dict, Iterable, Iterator, List, Optional, Sequence, Tuple

import click
import numpy as np

from .config import Config
from .errors import internal_error, interrupted
from .exits import InputError
from .result import MatchResult


def _write_probe(folder: Path) -> None:
    """Create and remove a file in ``folder`` (raises ``OSError`` when none can be written);
    nothing is left, and no name the run writes appears and vanishes."""
    import tempfile  # imported where used: the command line starts faster

    with tempfile.NamedTemporaryFile(dir=folder, prefix=".scalematch-check-"):
        pass


def check_out_dir(path: Path) -> None:
    """Create ``path`` and make sure a file can be written in it, before the work starts."""
    try:
        path.mkdir(parents=True, exist_ok=True)
        _write_probe(path)
    except OSError as exc:
        raise InputError(f"cannot write to the output directory {path}: "
                         f"{exc.strerror or exc}; choose another with --out-dir")


def check_out_file(path: Path, option: str) -> None:
    """Make sure ``path`` can be written before the work: its folder is created when missing (as
    ``--out-dir`` is), and the file can be opened for appending."""
    if path.is_dir():
        raise InputError(f"{option} {path} is a directory; give a file name")
    parent = path.parent if str(path.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot write {option} {path}: cannot create the folder {parent}: "
                         f"{exc.strerror or exc}")
    try:
        if path.exists():
            with open(path, "a"):
                pass
        else:  # a file beside it, not the file itself: nothing appears at ``path`` and vanishes
            _write_probe(parent)
    except OSError as exc:
        raise InputError(f"cannot write {option} {path}: {exc.strerror or exc}")


def _file_id(path: Any) -> Any:
    """What identifies the file ``path`` names: (device, inode) when it exists (so a hard link or
    another spelling is the same file), else its absolute path with links resolved."""
    try:
        st = os.stat(path)
        return (st.st_dev, st.st_ino)
    except (OSError, ValueError):
        return os.path.realpath(path)


def check_not_an_input(path: Path, inputs: Iterable[Any], option: str,
                       instead: str = "file") -> None:
    """Refuse (exit 2) to write ``path`` when it is one of ``inputs`` under any name: an output
    never overwrites an input (``--json v.png``, ``-o DIR`` holding an input named overlay.png,
    ``batch --output`` naming the CSV or an image)."""
    target = _file_id(path)
    for source in inputs:
        if _file_id(source) == target:
            same = "" if str(source) == str(path) else f" (the same file as {source})"
            raise InputError(f"{option} {path} is an input{same}: it would be overwritten; "
                             f"choose another {instead}")


def write_text(path: Path, text: str, option: str) -> None:
    try:
        path.write_text(text)
    except OSError as exc:
        raise InputError(f"cannot write {option} {path}: {exc.strerror or exc}")


@contextlib.contextmanager
def json_of_error(json_path: Optional[str], json_file: Optional[Path], low: str,
                  high: str, config: Config) -> Iterator[None]:
    """With ``--json``, the record of an error raised inside (``result.error_record``, as a
    batch writes it), so that a script reading the JSON learns why rather than finding nothing:
    kind "input" for a bad input (exit 2), "internal" for an unexpected error (exit 4: out of
    memory, a bug). The error goes on, and nothing more is written when the JSON cannot be
    written either. Ctrl-C writes nothing: it is not an answer about the pair."""
    try:
        yield
    except InputError as exc:
        _write_error_json(json_path, json_file, low, high, config, exc.format_message(), "input")
        raise
    except (click.ClickException, click.Abort):
        raise
    except Exception as exc:  # noqa: BLE001 (recorded, then passed on: exit 4 in main)
        if not interrupted(exc):
            _write_error_json(json_path, json_file, low, high, config, internal_error(exc),
                              "internal")
        raise


def _write_error_json(json_path: Optional[str], json_file: Optional[Path], low: str, high: str,
                      config: Config, message: str, kind: str) -> None:
    """The error record of ``--json`` where it can still be written (best effort: the error
    that brought it here matters more than one that writing it meets)."""
    if not json_path:
        return
    try:
        from .result import dumps, error_record

        text = dumps(error_record(low, high, message, kind, config), 2)
        if json_file is not None:
            check_out_file(json_file, "--json")
        write_json(text + "\n", json_file)
    except Exception:  # noqa: BLE001 (a full disk, memory gone: the first error is the one said)
        pass


def check_not_inputs(out_dir: Optional[Path], json_file: Optional[Path],
                     inputs: Sequence[str]) -> None:
    """Refuse (exit 2) an output file of ``-o`` or ``--json`` that is one of ``inputs`` or
    one of the other's files, and ``-o -`` (standard output is for ``--json -`` only: the
    pictures are files)."""
    if out_dir is not None and str(out_dir) == "-":
        raise InputError("--out-dir - : the pictures and matches.csv are files, not a stream; "
                         "give a folder (--json - writes the JSON to standard output)")
    if out_dir is not None:
        from .render import OUTPUT_FILES  # the pictures' modules: loaded for -o only

        for name in OUTPUT_FILES:
            check_not_an_input(out_dir / name, inputs, "--out-dir", "folder")
    if json_file is not None:
        check_not_an_input(json_file, inputs, "--json")
    if out_dir is not None and json_file is not None:
        for name in OUTPUT_FILES:
            if _file_id(out_dir / name) == _file_id(json_file):
                raise InputError(f"--json {json_file} is {name}, which --out-dir {out_dir} "
                                 f"writes: one would overwrite the other; name the JSON "
                                 f"otherwise (result.json, say)")


def check_writable(out_dir: Optional[Path], json_file: Optional[Path]) -> List[Path]:
    """Create the folders of ``-o`` and ``--json`` and make sure they can be written (exit 2);
    the folders of ``-o`` that this created, deepest first."""
    made = []
    if out_dir is not None:
        missing = out_dir.absolute()
        while not missing.exists():
            made.append(missing)
            missing = missing.parent
        check_out_dir(out_dir)
    if json_file is not None:
        check_out_file(json_file, "--json")
    return made


@contextlib.contextmanager
def removed_if_empty(folders: Sequence[Path]) -> Iterator[None]:
    """Remove ``folders`` (deepest first) again when the block inside fails and they are still
    empty: a match refused (exit 2) or failed leaves no empty ``-o`` folder behind."""
    try:
        yield
    except BaseException:
        for folder in folders:
            try:
                folder.rmdir()  # only an empty folder
            except OSError:
                break
        raise


def write_json(text: str, json_file: Optional[Path]) -> None:
    """The result's JSON to ``json_file``, or to stdout when None (``--json -``); exit 2 when
    it cannot be written (a full disk), as for a file (a closed pipe:
    ``cli.closed_pipe_ends_quietly``)."""
    if json_file is None:
        try:
            click.echo(text, nl=False)
        except BrokenPipeError:
            raise
        except OSError as exc:
            raise InputError(f"cannot write --json to stdout: {exc.strerror or exc}")
    else:
        write_text(json_file, text, "--json")


def write_pictures(out_dir: Path, low: str, high: str, low_img: np.ndarray, high_img: np.ndarray,
                   result: MatchResult, factors: Tuple[float, float]) -> Dict[str, Path]:
    """The files of ``-o`` (``render.write_outputs``), by name; exit 2 when they cannot be
    written."""
    from .render import write_outputs

    try:
        return write_outputs(out_dir, low, high, low_img, high_img, result, factors)
    except OSError as exc:
        raise InputError(f"cannot write the outputs to {out_dir}: {exc}")
