"""datasets: where the shared folder is looked for, and a lab command without it is a usage
error (exit 2) that says where it looked and how to point at the folder."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from scalematch.cli import cli
from scalematch.exits import EXIT_BAD_INPUT, EXIT_NO_MATCH
from scalematch.lab.datasets import SHARED_ENV, find_shared, shared_place

ROOT = Path(__file__).resolve().parents[2]

#: Every lab command that reads the shared folder, with the options it needs to get that far.
NEEDS_SHARED = [
    ("bench", [], "data/photos"),
    ("nulls", [], "data/photos"),
    ("real-pairs", [], "data"),
    ("ef-pairs", [], "data/ef"),
    ("3d-pairs", [], "data/photos"),
    ("3d-reference", [], "data/photos"),
    ("regress", [], "data/photos"),
    ("repeatability", [], "data/photos"),
    ("descriptor-study", [], "data/photos"),
]


@pytest.fixture
def empty_shared(tmp_path, monkeypatch):
    """$SCALEMATCH_SHARED set to an empty folder: the real ../shared is not looked at."""
    folder = tmp_path / "shared"
    folder.mkdir()
    monkeypatch.setenv(SHARED_ENV, str(folder))
    monkeypatch.chdir(tmp_path)  # whatever a command would write by default lands here
    return folder


@pytest.mark.parametrize("command, args, needs", NEEDS_SHARED,
                         ids=[c for c, _, _ in NEEDS_SHARED])
def test_a_lab_command_without_its_data_is_a_usage_error(empty_shared, command, args, needs):
    """Exit 2 (bad input or usage), not 1 (the command line's "no reliable match"), and one
    line naming the folder looked at, why there, and how to point at the shared folder."""
    result = CliRunner().invoke(cli, ["lab", command, *args], prog_name="scalematch")
    assert result.exit_code == EXIT_BAD_INPUT != EXIT_NO_MATCH, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.stderr
    assert f"{empty_shared / needs}" in lines[0] and f"${SHARED_ENV}" in lines[0], lines[0]
    assert f"{SHARED_ENV}=DIR" in lines[0], lines[0]
    assert "shared=" not in lines[0].replace(f"{SHARED_ENV}=", "")  # a Python word, not an option
    if command in ("repeatability", "descriptor-study"):  # no --shared: photos may be given
        assert "give image paths" in lines[0]
    else:
        assert "--shared DIR" in lines[0]


def test_a_given_shared_folder_is_named_as_given(tmp_path, empty_shared):
    """--shared is looked at, and said to be where it looked."""
    given = tmp_path / "elsewhere"
    given.mkdir()
    result = CliRunner().invoke(cli, ["lab", "bench", "--shared", str(given)],
                                prog_name="scalematch")
    assert result.exit_code == EXIT_BAD_INPUT
    assert f"{given / 'data' / 'photos'}, which is not there (from --shared)" in result.stderr


def test_the_shared_folder_is_looked_for_in_the_environment_then_beside_the_repository(
        tmp_path):
    place, why = shared_place({SHARED_ENV: str(tmp_path)})
    assert place == tmp_path and why == f"from ${SHARED_ENV}"
    assert find_shared({SHARED_ENV: str(tmp_path)}) == tmp_path
    assert find_shared({SHARED_ENV: str(tmp_path / "missing")}) is None
    place, why = shared_place({})
    assert place == ROOT.parent / "shared" and "not set" in why
