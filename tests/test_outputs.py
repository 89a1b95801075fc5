"""outputs: the files of ``-o`` and ``--json`` are checked before the work: their folders made,
never an input, nor one another's file."""

from __future__ import annotations

import json

import pytest

from test_cli import assert_one_line_error, needs_pipeline, run


@needs_pipeline
def test_json_into_a_missing_folder_creates_it_as_out_dir_does(tmp_path, flat_pair):
    js = tmp_path / "new" / "deeper" / "result.json"
    out = tmp_path / "new" / "pictures"
    result = run(*flat_pair, "--json", js, "-o", out, "-q")
    assert result.exit_code == 1, result.output  # no reliable match: both written all the same
    assert json.loads(js.read_text())["matched"] is False
    assert (out / "overlay.png").is_file()


def test_json_never_overwrites_an_input(flat_pair):
    low, high = flat_pair
    before = low.read_bytes()
    for target in (low, low.parent / "." / low.name):
        last = assert_one_line_error(run(low, high, "--json", target), "is an input")
        assert "--json" in last and "overwritten" in last
    assert low.read_bytes() == before


@pytest.mark.parametrize("name", ["overlay.png", "matches.csv", "scales.png"])
def test_json_onto_a_file_of_the_out_dir_is_refused_before_anything_is_written(tmp_path,
                                                                               flat_pair, name):
    folder = tmp_path / "out"
    for target in (folder / name, folder / "sub" / ".." / name):
        last = assert_one_line_error(run(*flat_pair, "-o", folder, "--json", target),
                                     f"is {name}, which --out-dir")
        assert "overwrite" in last
    assert not folder.exists()  # refused at the door: no folder made, nothing written


def test_out_dir_dash_is_refused_where_json_dash_means_stdout(tmp_path, flat_pair, monkeypatch):
    monkeypatch.chdir(tmp_path)
    last = assert_one_line_error(run(*flat_pair, "-o", "-"), "--out-dir -")
    assert "--json -" in last
    assert not (tmp_path / "-").exists()


@pytest.mark.parametrize("name", ["overlay.png", "matches.csv"])
def test_out_dir_never_overwrites_an_input(tmp_path, flat_pair, name):
    folder = tmp_path / "out"
    folder.mkdir()
    high = folder / name
    high.write_bytes(flat_pair[1].read_bytes())
    last = assert_one_line_error(run(flat_pair[0], high, "-o", folder), "is an input")
    assert "--out-dir" in last and "choose another folder" in last
    assert high.read_bytes() == flat_pair[1].read_bytes()
    assert sorted(p.name for p in folder.iterdir()) == [name]  # nothing else written
