"""options: the scales read, ``--set PATH=VALUE`` set on the nested Config, and the Config of
the options (their values refused by the command line: test_cli.py)."""

from __future__ import annotations

import pytest

from scalematch.options import build_config, parse_scales


def test_set_takes_groups_of_tilts_for_the_view_passes():
    config = build_config("default", None, None, None, {}, ["views.passes=2;4;6,8"])
    assert config.views.passes == ((2.0,), (4.0,), (6.0, 8.0))
    with pytest.raises(ValueError, match="views.passes needs groups of numbers split by ';'"):
        build_config("default", None, None, None, {}, ["views.passes=2;x"])
    with pytest.raises(ValueError, match="views.passes"):
        build_config("default", None, None, None, {}, ["views.passes=2;0.5"])  # a tilt < 1


def test_set_scales_reads_what_the_scales_option_reads():
    by_set = build_config("default", None, None, None, {}, ["scales=1-8"])
    assert by_set.scales == build_config("default", None, "1-8", None, {}, []).scales
    assert by_set.scales == (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0)


@pytest.mark.parametrize("item,needle", [
    ("harris=3", "'harris' is a group of parameters: set one of them, harris.NAME=VALUE"),
    ("ransac=1", "'ransac' is a group"),
    ("harris.threshold.x=2", "harris.threshold is a value, not a group"),
])
def test_set_on_a_group_is_a_usage_error_naming_its_parameters(item, needle):
    """A group given a value was taken as the value and failed deep in the search (exit 4)."""
    with pytest.raises(ValueError, match=needle):
        build_config("default", None, None, None, {}, [item])


def test_parse_scales():
    assert parse_scales("1-4") == (1.0, 2.0, 3.0, 4.0)
    assert parse_scales("2-4:0.5") == (2.0, 2.5, 3.0, 3.5, 4.0)
    assert parse_scales("1,2,3.5") == (1.0, 2.0, 3.5)
    assert parse_scales("1-3, 8") == (1.0, 2.0, 3.0, 8.0)
    for bad in ("8-1", "a-b", "", "1-4:0", "2:3"):  # "0.5-2" parses; Config refuses 0.5
        with pytest.raises(ValueError):
            parse_scales(bad)
    with pytest.raises(ValueError, match="'8-1' go down: write the range from the smaller "
                                         "scale, 1-8"):
        parse_scales("8-1")
    with pytest.raises(ValueError, match="step of scales '1-4:0' must be more than 0"):
        parse_scales("1-4:0")
