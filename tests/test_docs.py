"""Every code block of README.md and the user guide runs as written, from the repository root.

A fenced block whose language is ``bash``, ``sh``, ``shell`` or ``console`` runs in bash with
``set -e -o pipefail`` (a ``console`` block: only its ``$ `` lines); a ``python`` block runs in
a fresh interpreter, so it must stand on its own. Each block runs in a fresh folder that holds
what the repository root holds for it (``data``, ``scripts`` and ``.venv``, linked), with the
interpreter's ``bin`` first on ``PATH``: ``scalematch`` and ``python`` are the ones under test.

Words after the language in the fence say when a block does not run here:

* ``skip``: never (``make test`` inside a test, a server that does not return, ``pip install``);
* ``shared``: only when ``../shared`` is present (``SCALEMATCH_SHARED`` points at it);
* ``dask``: only when ``distributed`` is installed.

Blocks in any other language (``text`` for output) are not run.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import List, NamedTuple

import pytest

from scalematch.lab.datasets import find_shared

ROOT = Path(__file__).resolve().parents[1]
PAGES = ("README.md", "docs/GUIDE.md")
SHARED = find_shared() or ROOT.parent / "shared"  # $SCALEMATCH_SHARED, else ../shared
SHELLS = {"bash", "sh", "shell", "console"}
MARKS = {"skip", "shared", "dask"}
#: What a block reaches for in the repository root.
LINKED = ("data", "scripts")
#: Seconds a block may take (a demo match takes about one).
TIMEOUT_S = 120


class Block(NamedTuple):
    page: str
    line: int  #: of the opening fence, 1-based
    lang: str
    marks: frozenset
    text: str

    @property
    def id(self) -> str:
        return f"{self.page}:{self.line}"


def code_blocks(page: str) -> List[Block]:
    """The fenced blocks of ``page`` (```lang words ... ```), in order."""
    out, lines = [], (ROOT / page).read_text().splitlines()
    i = 0
    while i < len(lines):
        m = re.match(r"^(\s*)```\s*([\w+-]*)(.*)$", lines[i])
        if not m:
            i += 1
            continue
        indent, lang, rest = m.group(1), m.group(2).lower(), m.group(3).split()
        body, j = [], i + 1
        while j < len(lines) and lines[j].strip() != "```":
            body.append(lines[j][len(indent):] if lines[j].startswith(indent) else lines[j])
            j += 1
        out.append(Block(page, i + 1, lang, frozenset(rest), "\n".join(body) + "\n"))
        i = j + 1
    return out


def runnable(block: Block) -> bool:
    return block.lang in SHELLS or block.lang == "python"


BLOCKS = [b for page in PAGES for b in code_blocks(page) if runnable(b)]


def _shell_text(block: Block) -> str:
    if block.lang != "console":
        return block.text
    return "".join(line[2:] + "\n" for line in block.text.splitlines() if line.startswith("$ "))


def _workdir(tmp_path: Path) -> Path:
    """A folder that looks like the repository root to a block."""
    for name in LINKED:
        (tmp_path / name).symlink_to(ROOT / name)
    venv = Path(sys.prefix)
    if (venv / "bin" / "activate").is_file():
        (tmp_path / ".venv").symlink_to(venv)
    else:  # not run from a virtual environment: an activate that puts this interpreter first
        (tmp_path / ".venv" / "bin").mkdir(parents=True)
        (tmp_path / ".venv" / "bin" / "activate").write_text(
            f'export PATH="{Path(sys.executable).parent}:$PATH"\n')
    return tmp_path


def _env() -> dict:
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["SCALEMATCH_SHARED"] = str(SHARED)
    return env


@pytest.mark.parametrize("block", BLOCKS, ids=[b.id for b in BLOCKS])
def test_code_block_runs(block: Block, tmp_path):
    if "skip" in block.marks:
        pytest.skip("marked as not runnable here")
    if "shared" in block.marks and not (SHARED / "data" / "photos").is_dir():
        pytest.skip(f"the shared data is absent ({SHARED}; set SCALEMATCH_SHARED)")
    if "dask" in block.marks and importlib.util.find_spec("distributed") is None:
        pytest.skip("distributed is not installed")
    cwd = _workdir(tmp_path)
    if block.lang == "python":
        cmd = [sys.executable, "-c", block.text]
    else:
        cmd = ["bash", "-e", "-o", "pipefail", "-c", _shell_text(block)]
    run = subprocess.run(cmd, cwd=cwd, env=_env(), capture_output=True, text=True,
                         timeout=TIMEOUT_S, stdin=subprocess.DEVNULL)
    assert run.returncode == 0, (
        f"{block.id} exited {run.returncode}\n--- block\n{block.text}--- stdout\n"
        f"{run.stdout[-2000:]}--- stderr\n{run.stderr[-3000:]}")


def test_every_page_has_blocks_that_run():
    for page in PAGES:
        assert any(b.page == page and not b.marks & {"skip"} for b in BLOCKS), page


def test_marks_are_known_and_needs_are_marked():
    """A block that needs ../shared or Dask says so, so that it is skipped rather than failed
    where they are absent; a mark is one of MARKS."""
    for b in BLOCKS:
        assert b.marks <= MARKS, f"{b.id}: unknown words {sorted(b.marks - MARKS)}"
        if b.marks & {"skip"}:
            continue
        if "../shared" in b.text:
            assert "shared" in b.marks, f"{b.id} needs ../shared: mark it ```{b.lang} shared"
        if "--scheduler" in b.text or "distributed" in b.text:
            assert "dask" in b.marks, f"{b.id} needs Dask: mark it ```{b.lang} dask"


def test_each_line_of_the_readme_quick_start_runs_alone(tmp_path):
    """A new user copies one line of the command-line quick start, not the whole block: each
    runs alone in a fresh folder, after activating the environment (the third wrote into
    out/ with a shell redirection, and failed until the second had made out/)."""
    heading = (ROOT / "README.md").read_text().splitlines().index(
        "## Quick start: command line") + 1
    block = next(b for b in BLOCKS if b.page == "README.md" and b.lang in SHELLS
                 and b.line > heading)
    lines = [s for s in block.text.splitlines() if s.strip() and not s.startswith("source ")]
    assert len(lines) >= 3
    for k, line in enumerate(lines):
        (tmp_path / str(k)).mkdir()
        cwd = _workdir(tmp_path / str(k))
        run = subprocess.run(["bash", "-e", "-c", f"source .venv/bin/activate\n{line}\n"],
                             cwd=cwd, env=_env(), capture_output=True, text=True,
                             timeout=TIMEOUT_S, stdin=subprocess.DEVNULL)
        assert run.returncode == 0, (line, run.stderr[-2000:])


def test_the_no_views_figure_is_said_the_same_everywhere():
    """What --no-views saves is one measured figure, in the same words in the README, the
    guide, the design notes, both commands' --help and the slow "no"'s hint."""
    from dataclasses import replace

    from click.testing import CliRunner

    from scalematch.cli import cli
    from scalematch.options import NO_VIEWS_SPEEDUP
    from scalematch.report import SLOW_NO_HINT_S, slow_no_hint
    from scalematch.result import Direction, MatchResult, StepRecord

    def flat(text: str) -> str:
        return " ".join(text.split())

    for page in ("README.md", "docs/GUIDE.md", "docs/DESIGN.md"):
        assert NO_VIEWS_SPEEDUP in flat((ROOT / page).read_text()), page
    for command in ("match", "batch"):
        assert NO_VIEWS_SPEEDUP in flat(CliRunner().invoke(cli, [command, "--help"]).output)
    step = StepRecord(Direction.GIVEN, 0, 1, 1, 3.0, False)
    slow = MatchResult(matched=False, model="similarity", reason="too few inliers",
                       timings={"total": SLOW_NO_HINT_S + 1},
                       search=(step, replace(step, view_pass=1, views=5)))
    assert NO_VIEWS_SPEEDUP in slow_no_hint(slow)


def test_the_batch_examples_of_readme_then_guide_run_in_one_folder(tmp_path):
    """A new user runs the README's batch example, then the guide's, in one checkout: the
    guide's must not resume the README's file (it did: "resuming: 2 of 2", and its CSV columns
    never appeared)."""
    def batch_block(page: str) -> Block:
        return next(b for b in BLOCKS if b.page == page and b.lang in SHELLS
                    and "scalematch batch" in b.text and not b.marks)

    cwd = _workdir(tmp_path)
    for page in ("README.md", "docs/GUIDE.md"):
        text = batch_block(page).text
        if page == "README.md":  # the quick start's batch lines, after its activation
            text = "\n".join(line for line in text.splitlines()
                             if line.startswith(("mkdir", "printf", "scalematch batch")))
        run = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", text], cwd=cwd, env=_env(),
                             capture_output=True, text=True, timeout=TIMEOUT_S,
                             stdin=subprocess.DEVNULL)
        assert run.returncode == 0, (page, run.stderr[-2000:])
        assert "resuming" not in run.stderr.splitlines()[0], (page, run.stderr)
    assert "('demo', 'given')" in run.stdout and "('swapped', 'swapped')" in run.stdout


#: Figures the docs and the help give in more than one place: (name, pattern whose groups are
#: the figure). Each is measured by the command its page names beside it (docs/design/SPEED.md
#: gives the commands); measured again, it changes everywhere, never in one place only.
REPEATED_FIGURES = (
    ("--no-views sooner", r"about ([\d.]+) times sooner on 1 MP images,? ([\d.]+(?: to [\d.]+)?) times on "
                          r"12-16 MP"),
    ("tilt-4 sooner", r"tilt-4`? \(a \"no\" ([\d.]+) times sooner|([\d.]+) times sooner \(a "
                      r"median"),
    ("SIFT's 12-16 MP no", r"SIFT(?:'s)? ([\d.]+(?: to [\d.]+)? s) and ([\d.]+(?: to [\d.]+)? "
                           r"GB)"),
    ("null set, in process", r"median (?:\"no\" of )?([\d.]+) s against SIFT's ([\d.]+) s in "
                             r"the same runs"),
    ("12-16 MP no", r"a median ([\d.]+ s) \(at most ([\d.]+ s)\) and ([\d.]+ MB)"),
)
#: Where the figures are said: the pages of users and maintainers, the code's help texts and hints
FIGURE_PAGES = ("README.md", "docs/GUIDE.md", "docs/DESIGN.md", "docs/design/SPEED.md",
                "scalematch/cli.py", "scalematch/options.py", "scalematch/report.py",
                "scalematch/config.py")


def test_a_figure_said_in_several_places_has_one_value():
    from click.testing import CliRunner

    from scalematch.cli import cli

    def flat(text: str) -> str:
        return " ".join(text.replace("#", " ").split())

    texts = {page: flat((ROOT / page).read_text()) for page in FIGURE_PAGES}
    for command in ("match", "batch"):
        texts[f"{command} --help"] = flat(CliRunner().invoke(cli, [command, "--help"]).output)
    for name, pattern in REPEATED_FIGURES:
        said = {}
        for where, text in texts.items():
            for m in re.finditer(pattern, text, re.I):
                said.setdefault(tuple(g for g in m.groups() if g is not None), []).append(where)
        assert said, f"{name}: said nowhere (pattern {pattern!r})"
        assert len(said) == 1, f"{name} has {len(said)} values: {said}"


def test_the_readme_verdict_is_the_tool_s_on_the_demo_pair():
    """The verdict the README shows for the demo pair is the one the tool prints, word for word,
    but for the time it took, which follows the machine."""
    from scalematch import match
    from scalematch.imageio import read_grey
    from scalematch.report import summary

    shown = re.search(r"^(matched \(.*); matching took [\d.]+ s$", (ROOT / "README.md").read_text(),
                      re.M)
    assert shown, "the README shows no verdict of the demo pair"
    result = match(read_grey(ROOT / "data" / "demo_low.png"), read_grey(ROOT / "data" / "demo_high.png"))
    printed = summary(result)
    assert printed.rsplit("; matching took", 1)[0] == shown.group(1)
