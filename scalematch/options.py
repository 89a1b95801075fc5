"""The options of a match, shared by ``match`` and ``batch`` (click decorators), and the
``Config`` they give: ``--scales`` read, ``--set PATH=VALUE`` set on the nested frozen
dataclasses, each value refused with a message that names its option (exit 2)."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import re
from pathlib import Path
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence, Tuple

import click

from .config import MAX_SCALES, MAX_SEED, MIN_WORKING_SIDE_PX, MODELS, MODES, ORDERS, Config
from .exits import InputError
from .imagefile import DEFAULT_MAX_PIXELS


#: What --no-views saves on a "no", as measured (docs/design/SPEED.md, 'The time of a "no"':
#: medians, the two searches alternately on one 2-core machine): said in these words in
#: --help, the slow "no"'s hint, README.md and docs/GUIDE.md (tests/test_docs.py)
NO_VIEWS_SPEEDUP = "about 3 times sooner on 1 MP images, 1.5 to 2 times on 12-16 MP photos"

#: Named threshold options: (option, Config paths, type, help). An option is offered only when
#: its path exists in ``Config()``; any other field can be set with ``--set PATH=VALUE``. A
#: ``{path}`` in a help is that field's default. The values that mean something are checked by
#: the parameters themselves (``scalematch.checks``), so an option, ``--set`` and the library
#: refuse a value with the same message.
THRESHOLD_OPTIONS = (
    ("--harris-threshold", ("harris.threshold", "harris_low.threshold"), click.FLOAT,
     "Cornerness threshold of the scale-adapted Harris detector (both images), "
     "(grey level/px)^4, >= 0."),
    ("--ratio-test", ("matcher.ratio",), click.FLOAT,
     "Nearest / second-nearest descriptor distance ratio to keep a candidate match, in (0, 1]."),
    ("--ransac-threshold", ("ransac.threshold_px",), click.FLOAT,
     "RANSAC inlier distance, low-resolution px, > 0."),
    ("--ransac-iterations", ("ransac.max_iters",), click.INT,
     "RANSAC iterations at most, >= 1."),
    ("--min-inliers", ("decision.min_inliers",), click.INT,
     "Inliers a match needs to count as reliable by their number, >= 0; with fewer, down to "
     "{decision.few_min_inliers}, a match is accepted only when it is far beyond chance and the "
     "pixel check confirms it (--set decision.few_min_inliers=N)."),
    ("--max-log-nfa", ("decision.max_log_nfa",), click.FLOAT,
     "Largest log10 number of false alarms for a match to count as reliable (lower: stricter)."),
)


def parse_scales(text: str) -> Tuple[float, ...]:
    """"1-8" (unit steps), "2-12:0.5" (steps of 0.5), "1,2,3.5" or a mix ("1-4,6,8") -> scales.

    Raises ``ValueError`` with a message that says the accepted forms, and for more than
    ``MAX_SCALES`` scales before they are listed.

    >>> parse_scales("1-4,6")
    (1.0, 2.0, 3.0, 4.0, 6.0)
    >>> parse_scales("1-16:0.001")
    Traceback (most recent call last):
    ...
    ValueError: scales '1-16:0.001' are 15001 scales, more than the 64 searched at most; take a larger step ("1-16:0.25" is 61)
    >>> parse_scales("1-16:1e-300")
    Traceback (most recent call last):
    ...
    ValueError: scales '1-16:1e-300' are about 1.5e+301 scales, more than the 64 searched at most; take a larger step ("1-16:0.25" is 61)
    """
    out: List[float] = []
    forms = 'use e.g. "1-8", "2-12:0.5" or "1,2,3.5"'
    for item in text.replace(" ", "").split(","):
        if not item:
            continue
        try:
            if "-" in item[1:]:
                out.extend(_scale_range(item, MAX_SCALES - len(out)))
            elif ":" in item:
                raise ValueError
            else:
                out.append(float(item))
        except ValueError as exc:
            if "searched at most" in str(exc):
                raise
            if str(exc).startswith(("scales ", "the step")):
                raise ValueError(f"{exc}; {forms}") from None
            raise ValueError(f"cannot read scales {text!r} at {item!r}; {forms}") from None
    if not out:
        raise ValueError(f"no scales in {text!r}; {forms}")
    return tuple(sorted(set(out)))  # Config checks that each is >= 1


def _has_path(obj: Any, path: str) -> bool:
    for name in path.split("."):
        if not dataclasses.is_dataclass(obj) or name not in {f.name for f in dataclasses.fields(obj)}:
            return False
        obj = getattr(obj, name)
    return True


def _scale_range(item: str, room: int) -> List[float]:
    """The scales of one range "lo-hi" or "lo-hi:step"; ``ValueError`` when it is malformed or
    holds more than ``room`` scales (said before they are listed)."""
    rng, _, step_txt = item.partition(":")
    lo_txt, _, hi_txt = rng.partition("-")
    lo, hi = float(lo_txt), float(hi_txt)
    step = float(step_txt) if step_txt else 1.0
    if not all(math.isfinite(v) for v in (lo, hi, step)):
        raise ValueError(f"scales {item!r} are not finite numbers")
    if hi < lo:
        raise ValueError(f"scales {item!r} go down: write the range from the smaller scale, "
                         f"{hi_txt}-{lo_txt}")
    if not step > 0:
        raise ValueError(f"the step of scales {item!r} must be more than 0")
    span = (hi - lo) / step  # inf where the step is too small for a float to count the steps
    count = math.floor(span + 1e-9) + 1 if math.isfinite(span) else math.inf
    if count > room:
        many = (f"{count} scales" if count < 1e6 else f"about {count:.1e} scales"
                if math.isfinite(count) else "more scales than a float can count")
        raise ValueError(f"scales {item!r} are {many}, more than the {MAX_SCALES} searched "
                         f"at most; take a larger step (\"1-16:0.25\" is 61)")
    n = int(count)
    return [round(lo + k * step, 6) for k in range(n)]


def _coerce(text: str, current: Any, path: str) -> Any:
    """``text`` converted to the type of the field's current value."""
    if path == "scales":  # as --scales writes them: "1-8", "2-12:0.5", "1,2,3.5"
        return parse_scales(text)
    try:
        if isinstance(current, bool):
            low = text.strip().lower()
            if low in ("1", "true", "yes", "on"):
                return True
            if low in ("0", "false", "no", "off"):
                return False
            raise ValueError
        if isinstance(current, int):
            return int(text)
        if isinstance(current, float):
            return float(text)
        if isinstance(current, tuple):
            return _coerce_tuple(text, current)
        if current is None:
            try:
                return float(text) if "." in text or "e" in text.lower() else int(text)
            except ValueError:
                return text
        if isinstance(current, Path):
            return Path(text)
    except ValueError:
        kind = ("groups of numbers split by ';' (e.g. 2;4;6,8)"
                if isinstance(current, tuple) and current and isinstance(current[0], tuple)
                else "comma-separated numbers (e.g. 1,2,4)" if isinstance(current, tuple)
                else f"a {type(current).__name__} value")
        raise ValueError(f"{path} needs {kind}, got {text!r}") from None
    return text


def _coerce_tuple(text: str, current: tuple) -> tuple:
    """Comma-separated numbers; for a tuple of tuples (views.passes), groups split by ";",
    e.g. "2;4;6,8". ``ValueError`` for anything else."""
    if current and isinstance(current[0], tuple):
        return tuple(tuple(float(v) for v in group.split(",") if v.strip())
                     for group in text.split(";") if group.strip())
    return tuple(float(v) for v in text.split(",") if v.strip())


def set_path(config: Any, path: str, value: Any, whole: Optional[str] = None) -> Any:
    """A copy of the (nested, frozen) dataclass ``config`` with ``path`` ("a.b.c") set
    (``whole``: the path as the user wrote it, for the messages; ``path`` by default)."""
    whole = whole or path
    head, _, rest = path.partition(".")
    done = whole[:len(whole) - len(path)]  # the groups already entered, "views." say
    if not dataclasses.is_dataclass(config):
        raise ValueError(f"no parameter {whole!r}: {done.rstrip('.')} is a value, not a group")
    if head not in {f.name for f in dataclasses.fields(config)}:
        names = ", ".join(f.name for f in dataclasses.fields(config))
        raise ValueError(f"no parameter {whole!r} (known here: {names})")
    current = getattr(config, head)
    if rest:
        return dataclasses.replace(config, **{head: set_path(current, rest, value, whole)})
    if dataclasses.is_dataclass(current) and not dataclasses.is_dataclass(value):
        names = ", ".join(f.name for f in dataclasses.fields(current))
        raise ValueError(f"{whole!r} is a group of parameters: set one of them, "
                         f"{whole}.NAME=VALUE (its names: {names})")
    if isinstance(value, str):
        value = _coerce(value, current, whole)
    return dataclasses.replace(config, **{head: value})


@contextlib.contextmanager
def about(option: str) -> Iterator[None]:
    """A ``ValueError`` raised inside names ``option`` first (``--scales 0: scales must be >=
    1, got 0.0``), so that the message says which of the options given was refused."""
    try:
        yield
    except ValueError as exc:
        raise ValueError(f"{option}: {exc}") from None


def build_config(mode: str, model: Optional[str], scales: Optional[str], seed: Optional[int],
                 thresholds: Dict[str, Any], settings: Sequence[str],
                 options: Optional[Dict[str, str]] = None) -> Config:
    """The Config of the command-line options; ``ValueError`` with a message when one is bad,
    naming the option (``options``: the option of each threshold's path, "--ratio-test" say).
    """
    config = Config.preset(mode)  # the modes are presets of the same names
    changes: Dict[str, Any] = {}
    if model is not None:
        changes["model"] = model
    if seed is not None:
        changes["seed"] = seed
    if changes:
        config = dataclasses.replace(config, **changes)
    if scales is not None:
        with about(f"--scales {scales}"):
            config = dataclasses.replace(config, scales=parse_scales(scales))
    for path, value in thresholds.items():
        if value is not None:
            with about(f"{(options or {}).get(path, path)} {value}"):
                config = set_path(config, path, value)
    for item in settings:
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise ValueError(f"--set needs PATH=VALUE (e.g. harris.threshold=50), got {item!r}")
        with about(f"--set {item}"):
            config = set_path(config, key.strip(), value.strip())
    return config


def matching_options(f: Callable) -> Callable:
    """The options shared by ``match`` and ``batch``: what is matched and how."""
    for opt in reversed(_search_options() + _threshold_options() + _value_options()):
        f = opt(f)
    return f


def _search_options() -> List[Callable]:
    """The options of the search: the model, the mode, the order, views, time, no-data, size."""
    return [
        click.option("--model", type=click.Choice(MODELS), default=None,
                     help="Transform from high-res px to low-res px. similarity: searched "
                          "at every scale, the answer rising to an affine map or a homography "
                          "where the pixels ask for it (a plane in perspective); affine: no "
                          "further than an affine map; homography: as the default; "
                          "fundamental: a 3-D scene's epipolar geometry. [default: similarity]"),
        click.option("--mode", type=click.Choice(MODES), default="default", show_default=True,
                     help="'paper': the method as published (jets, Mahalanobis, semi-local "
                          "constraints, scales 1-8)."),
        click.option("--order", type=click.Choice(ORDERS), default="auto", show_default=True,
                     help="'auto': find which image is the finer one (the given order is tried "
                          "first, then the other; the JSON says which). 'given': LOW is the "
                          "coarser image."),
        click.option("--views/--no-views", "views", default=True, show_default=True,
                     help="When nothing matches, simulate tilted views of both images "
                          "(oblique shots; the coarser one's views solve a finer image seen "
                          "more obliquely than its zoom): tilts 2, then 4, then 6 and 8, each "
                          "pass one vote over all their pairs, and only when the earlier passes "
                          "found nothing. They are most of the time of a \"no\": with "
                          f"--no-views a \"no\" comes {NO_VIEWS_SPEEDUP} "
                          "(docs/design/SPEED.md; for archives of mostly unrelated pairs), but "
                          "pairs only a tilted view solves are missed; --set "
                          "\"views.passes=2;4\" leaves out the steepest pass (1.6x sooner)."),
        click.option("--time-budget", type=float, default=None, metavar="SECONDS",
                     help="Start no further step of the search after SECONDS (the given "
                          "order's plain search always runs): a pair with no match is answered "
                          "sooner, but one only the other order or a tilted view would solve is "
                          "missed, and the answer then depends on the machine's speed. "
                          "[default: no limit]"),
        click.option("--nodata", default=None, metavar="auto|none|VALUE",
                     help="Where an image shows no scene: 'auto' finds a canvas left by a "
                          "rotation or a warp (a region of one grey level at the border, "
                          "bounded by the picture's straight, slanted edges); VALUE declares a "
                          "grey level that is no-data wherever it covers a region (as GDAL "
                          "rasters declare theirs; 0-255 as the image's 8-bit levels); 'none': "
                          "every pixel is scene. No-data keeps no points and is left out of "
                          "the pixel tests; a clipped sky or a backdrop is scene. The JSON's "
                          "low.nodata and high.nodata say what was taken. [default: auto]"),
        click.option("--working-size", type=click.INT, default=None, metavar="PX",
                     help="Match an image whose longer side exceeds PX at that size and give "
                          f"the answer in its own pixels: 0 (always full size) or at least "
                          f"{MIN_WORKING_SIDE_PX}; the high image only with --order auto. "
                          "[default: 2048]"),
        click.option("--scales", metavar="LIST",
                     help='Scales s of the high-res image to try: "1-8", "2-12:0.5" or '
                          '"1,2,3.5". [default: 1-16 in third octaves; paper mode 1-8]'),
    ]


def _threshold_options() -> List[Callable]:
    """The decision's thresholds as options (``THRESHOLD_OPTIONS``), their defaults shown."""
    base, opts = Config(), []
    for name, paths, typ, text in THRESHOLD_OPTIONS:
        paths = [p for p in paths if _has_path(base, p)]
        if paths:
            dest = "thr_" + name[2:].replace("-", "_")
            opts.append(click.option(name, dest, type=typ, default=None,
                                     help=f"{_with_defaults(text, base)} (Config "
                                          f"{', '.join(paths)}) [default: {_get(base, paths[0])}]"))
    return opts


def _value_options() -> List[Callable]:
    """Any parameter by its path, the seed, and the largest image read."""
    return [
        click.option("--set", "settings", multiple=True, metavar="PATH=VALUE",
                     help="Set any Config field, e.g. --set harris.sigma_tilde=2.5 (repeatable)."),
        click.option("--seed", type=click.IntRange(0, MAX_SEED), default=None,
                     help="Seed of all randomness (RANSAC); same input, same output. "
                          "[default: 0]"),
        click.option("--max-pixels", type=click.IntRange(min=1), default=DEFAULT_MAX_PIXELS,
                     show_default=True,
                     help="Refuse images with more pixels than this, from their header, before "
                          "decoding them (OpenCV itself decodes at most 1073741824)."),
    ]


def _get(obj: Any, path: str) -> Any:
    for name in path.split("."):
        obj = getattr(obj, name)
    return obj


def _with_defaults(text: str, config: Any) -> str:
    """``text`` with each ``{path}`` of a field of ``config`` replaced by its value.

    >>> _with_defaults("down to {decision.few_min_inliers} inliers", Config())
    'down to 4 inliers'
    """
    return re.sub(r"\{([a-z_.]+)\}", lambda m: str(_get(config, m.group(1)))
                  if _has_path(config, m.group(1)) else m.group(0), text)


def config_from(kwargs: Dict[str, Any]) -> Config:
    base = Config()
    thresholds, options = {}, {}
    for name, paths, _, _ in THRESHOLD_OPTIONS:
        value = kwargs.pop("thr_" + name[2:].replace("-", "_"), None)
        for p in paths:
            if _has_path(base, p):
                thresholds[p], options[p] = value, name
    try:
        config = build_config(kwargs.pop("mode"), kwargs.pop("model"), kwargs.pop("scales"),
                              kwargs.pop("seed"), thresholds,
                              tuple(kwargs.pop("settings"))
                              + (f"order={kwargs.pop('order')}",
                                 f"views.enabled={kwargs.pop('views')}"), options)
        budget = kwargs.pop("time_budget")
        if budget is not None and math.isinf(budget) and budget > 0:
            budget = None  # inf: no limit, as without the option
        if budget is not None:
            if not budget > 0:
                raise ValueError(f"--time-budget must be more than 0 seconds, got {budget:g}")
            config = set_path(config, "time_budget_s", float(budget))
        nodata = kwargs.pop("nodata")
        if nodata is not None:
            from .stages.nodata import parse_rule

            config = set_path(config, "nodata.rule", parse_rule(nodata))
        working = kwargs.pop("working_size")
        if working is not None and (working < 0 or 0 < working < MIN_WORKING_SIDE_PX):
            raise ValueError(f"--working-size must be 0 (always full size) or at least "
                             f"{MIN_WORKING_SIDE_PX} px, got {working}")
        if working is not None:  # 0: always full size
            config = dataclasses.replace(config, low_max_side=working or None,
                                         high_max_side=working or None)
    except ValueError as exc:
        raise InputError(str(exc))
    return config
