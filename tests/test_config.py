"""config: one Config, the named presets, the checks of its values."""

from __future__ import annotations

import pytest

from scalematch.config import MODES, PRESETS, Config, ProbeParams
from scalematch.stages.detector import PAPER_SCALES


def test_the_modes_are_presets_and_presets_take_changes():
    assert set(MODES) <= set(PRESETS)
    assert Config.preset("default") == Config()
    assert Config.preset("paper") == Config.paper()
    paper = Config.preset("paper", seed=7, model="homography")
    assert (paper.mode, paper.scales, paper.seed, paper.model) == ("paper", PAPER_SCALES, 7,
                                                                   "homography")
    assert paper.probe == ProbeParams(enabled=False)


def test_every_preset_is_a_valid_config_and_the_variants_differ_from_their_base():
    configs = {name: Config.preset(name) for name in PRESETS}
    assert len(set(map(repr, configs.values()))) == len(configs)  # no two the same
    assert configs["paper-finer-scales"].scales == Config().scales
    assert configs["default-no-rotation-check"].orientation.max_peaks == 1


def test_an_unknown_preset_names_the_known_ones():
    with pytest.raises(ValueError, match="unknown preset 'fast'; one of default, paper"):
        Config.preset("fast")
