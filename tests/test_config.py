"""config: one Config, the named presets, the checks of its values."""

from __future__ import annotations

from dataclasses import fields

import pytest

from scalematch.config import MODES, PRESETS, Config, ProbeParams
from scalematch.stages.acontrario import DecisionParams
from scalematch.stages.detector import PAPER_SCALES, HarrisParams
from scalematch.stages.estimator import RansacParams
from scalematch.stages.guided import GuidedParams
from scalematch.stages.matcher import MatcherParams
from scalematch.stages.pixelcheck import PixelParams
from scalematch.stages.views import ViewParams


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
    assert Config().views.passes == ((2.0,), (4.0,), (6.0, 8.0))
    assert configs["tilt-4"].views.passes == Config().views.passes[:2]  # without the steepest
    assert configs["budget-1s"].time_budget_s == 1.0 and Config().time_budget_s is None


def test_an_unknown_preset_names_the_known_ones():
    with pytest.raises(ValueError, match="unknown preset 'fast'; one of default, paper"):
        Config.preset("fast")


@pytest.mark.parametrize("make,message", [
    (lambda: Config(matcher=MatcherParams(ratio=5.0)), "matcher.ratio must be in (0, 1], got 5.0"),
    (lambda: Config(time_budget_s=0.0), "time_budget_s must be > 0, got 0.0"),
    (lambda: Config(ransac=RansacParams(threshold_px=-1)),
     "ransac.threshold_px must be > 0, got -1"),
    (lambda: RansacParams(max_iters=2.5), "ransac.max_iters must be an integer in [1, 100000], got 2.5"),
    # what multiplies the work of a search is bounded where it is made
    (lambda: RansacParams(max_iters=100_001), "ransac.max_iters must be an integer in [1, 100000]"),
    (lambda: Config(scales=tuple(1 + k / 10 for k in range(65))),
     "scales: at most 64 are searched, got 65"),
    (lambda: ViewParams(longitude_step_deg=10.0), "the passes hold 360 views"),
    (lambda: HarrisParams(threshold=float("nan")), "harris.threshold must be >= 0, got nan"),
    (lambda: DecisionParams(min_inside=1.5), "decision.min_inside must be in [0, 1]"),
    (lambda: ViewParams(passes=((0.5,),)), "views.passes must be >= 1, got 0.5"),
    (lambda: ProbeParams(points=0), "probe.points must be an integer in [1, 2147483647], got 0"),
    (lambda: Config(scales=(0.5, 2.0)), "scales must be >= 1, got 0.5"),
    (lambda: Config(scales=()), "scales must hold at least one scale"),
    (lambda: Config(low_max_side=10), "low_max_side must be an integer >= 64, got 10"),
    (lambda: Config(order="sideways"), "order must be one of"),
    (lambda: GuidedParams(radius_px=0.0), "guided.radius_px must be > 0, got 0.0"),
    (lambda: GuidedParams(max_rounds=0), "guided.max_rounds must be an integer in [1, 2147483647], got 0"),
    (lambda: PixelParams(scale_step=0.8), "pixel.scale_step must be >= 1, got 0.8"),
    (lambda: PixelParams(min_overlap_px=2.5), "pixel.min_overlap_px must be an integer in [1, 2147483647]"),
])
def test_every_params_refuses_values_that_mean_nothing(make, message):
    """The ranges live in the parameters themselves, so the library refuses what the
    command line refuses, with the message that names the value as --set does."""
    with pytest.raises(ValueError) as exc:
        make()
    assert message in str(exc.value)


def test_the_command_line_says_what_the_library_says():
    from click.testing import CliRunner

    from scalematch.cli import cli

    with pytest.raises(ValueError) as exc:
        Config(ransac=RansacParams(threshold_px=-1.0))
    out = CliRunner().invoke(cli, ["data/demo_low.png", "data/demo_high.png",
                                   "--set", "ransac.threshold_px=-1"])
    assert out.exit_code == 2 and str(exc.value) in out.output


def test_the_defaults_and_presets_pass_their_own_checks():
    for name in PRESETS:
        Config.preset(name)  # would raise
    assert Config().ransac == RansacParams()


def test_guided_growth_and_the_pixel_tests_are_set_and_recorded_as_the_rest():
    """They decide match or no match: fields of Config (defaults as the stages'), set with
    --set guided.X / pixel.X, recorded in the result's config."""
    from scalematch.batchresume import config_json
    from scalematch.options import build_config

    assert Config().guided == GuidedParams() and Config().pixel == PixelParams()
    config = build_config("default", None, None, None, {},
                          ["guided.radius_px=5", "guided.use_orientation=off",
                           "pixel.min_overlap_px=300"])
    assert config.guided == GuidedParams(radius_px=5.0, use_orientation=False)
    assert config.pixel == PixelParams(min_overlap_px=300)
    recorded = config_json(config)
    assert recorded["guided"]["radius_px"] == 5.0 and recorded["pixel"]["min_overlap_px"] == 300
    with pytest.raises(ValueError, match="pixel.vouch_radius must be > 0"):
        build_config("default", None, None, None, {}, ["pixel.vouch_radius=0"])


@pytest.mark.parametrize("make,kind,message", [
    (lambda: Config(ransac=3), TypeError,
     "ransac must be a RansacParams, not int: change one of its values with "
     "replace(Config().ransac, NAME=VALUE)"),
    (lambda: Config(harris={"sigma": 1.0}), TypeError, "harris must be a HarrisParams, not dict"),
    (lambda: Config(scales=4), TypeError, "scales must be a tuple of scales >= 1"),
    (lambda: Config(seed=2**31), ValueError,
     "seed must be an integer in [0, 2147483647], got 2147483648"),
    (lambda: Config(seed=-1), ValueError, "seed must be an integer in [0, 2147483647], got -1"),
])
def test_a_config_that_cannot_be_matched_is_refused_when_it_is_made(make, kind, message):
    """Not later, inside match ("replace() should be called on dataclass instances") or inside
    OpenCV ("integer won't fit into a C int")."""
    with pytest.raises(kind) as exc:
        make()
    assert message in str(exc.value)
    assert Config(seed=2**31 - 1).seed == 2**31 - 1  # the largest seed OpenCV takes


def test_a_config_shows_only_what_differs_from_the_default():
    """help(scalematch.match) shows its default config as Config(), not 2.5 KB of values."""
    import inspect

    import scalematch

    assert repr(Config()) == "Config()"
    assert repr(Config(seed=3, model="affine")) == "Config(model='affine', seed=3)"
    assert "probe=ProbeParams(enabled=False" in repr(Config.paper())
    signature = str(inspect.signature(scalematch.match))
    assert "config: 'Config' = Config()," in signature and len(signature) < 300


def test_every_number_of_every_parameter_group_has_its_range_declared_once():
    """Each group's ``BOUNDS`` table names every numeric field it holds, and only those: a new
    parameter cannot be added without its range, nor a range left for a field that went."""
    from scalematch.config import _groups

    groups = dict(_groups(), config=Config)
    for owner, kind in groups.items():
        numbers = {f.name for f in fields(kind)
                   if isinstance(getattr(kind(), f.name), (int, float))
                   and not isinstance(getattr(kind(), f.name), bool)}
        optional = {name for name, b in kind.BOUNDS.items() if b.optional}
        assert numbers <= set(kind.BOUNDS), (owner, numbers - set(kind.BOUNDS))
        assert set(kind.BOUNDS) - optional <= numbers, (owner, set(kind.BOUNDS) - numbers)


def test_a_count_past_what_opencv_takes_is_refused_when_it_is_made():
    """OpenCV takes its counts as C ints: 2^31 points is refused by the check, naming the
    value, not by OpenCV deep inside a match (an internal error)."""
    with pytest.raises(ValueError, match=r"harris.max_points must be an integer in \[0, 2147483647\]"):
        HarrisParams(max_points=2**31)
    assert HarrisParams(max_points=2**31 - 1).max_points == 2**31 - 1


def test_the_bounds_on_work_admit_the_largest_settings_the_docs_name():
    """64 scales, 200 views and 100,000 RANSAC iterations hold what the presets and the guide
    use: half steps over 1-32, a longitude step of 18 degrees, the default cap times 20."""
    assert len(Config(scales=tuple(1 + k / 2 for k in range(63))).scales) == 63
    assert ViewParams(longitude_step_deg=18.0).longitude_step_deg == 18.0
    assert RansacParams(max_iters=100_000).max_iters == 100_000
