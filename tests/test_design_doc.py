"""docs/DESIGN.md is where a maintainer starts: everything it cites exists, and the docs' links
resolve.

Each backticked token of DESIGN.md is read as what it looks like:

* a file, ``stages/views.py`` (or a folder, ``scalematch/lab/``): it is in the package;
* a dotted name, ``working.in_original``, ``Config.paper()``, ``View.to_view``: its head is a
  product module (``scalematch/<head>.py`` or ``scalematch/stages/<head>.py``) or a class defined
  in the package, and every later part is an attribute of what comes before it (a dataclass or
  named-tuple field counts);
* a bare name in a row of the table of modules, ``run_step`` beside ``pipeline.py``: an attribute
  of one of the row's modules or of a class they define, a preset, a name of the public API
  (``scalematch.match``) or a command. So renaming a cited function fails here, whatever other
  function of that name exists elsewhere. A row's parameters are ``Config``'s fields;
* a bare name in the prose, ``Config``, ``match()``: a product module, a preset, a command, or a
  name the package defines (``def name``, ``class name``, ``name =`` or ``name: type =``);
* an option, ``--no-views``, ``--mode paper``: an option the command line declares.

Tokens with a space that are not options (``import scalematch``) and patterns (``*Params``) are
not names. A failure lists every token not found, and what was looked for.
"""

from __future__ import annotations

import importlib
import inspect
import re
from pathlib import Path
from types import ModuleType
from typing import List, NamedTuple, Optional, Sequence

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "scalematch"
DESIGN = ROOT / "docs" / "DESIGN.md"
#: Pages whose relative links must lead to a file of the repository
LINKED_PAGES = (ROOT / "README.md", ROOT / "scripts" / "README.md",
                *sorted((ROOT / "docs").rglob("*.md")))
#: A backticked token of a Markdown line
TOKEN = re.compile(r"`([^`\n]+)`")


class Known(NamedTuple):
    """What a bare name may be besides a module's attribute: the presets, the public API's
    names, the commands, and the source of the modules that declare the options."""

    presets: frozenset
    public: frozenset
    commands: frozenset
    options: str


@pytest.fixture(scope="module")
def known() -> Known:
    import scalematch
    from scalematch.cli import cli
    from scalematch.config import PRESETS

    options = "\n".join((PACKAGE / name).read_text() for name in ("cli.py", "options.py"))
    return Known(frozenset(PRESETS), frozenset(scalematch.__all__),
                 frozenset(cli.list_commands(None)), options)


def product_sources() -> List[Path]:
    """The product package's modules (the research code of ``scalematch/lab`` left out)."""
    return [p for p in sorted(PACKAGE.rglob("*.py"))
            if "lab" not in p.relative_to(PACKAGE).parts]


def cited_tokens(text: str) -> List[str]:
    """Every backticked token of ``text``, in order, once each."""
    return list(dict.fromkeys(TOKEN.findall(text)))


def module_name(head: str) -> Optional[str]:
    """The dotted name of the product module called ``head`` (``pipeline``, ``views``, ``plan``), or
    of the file ``head`` (``stages/views.py``, ``__init__.py``); None when there is none."""
    if head.endswith(".py"):
        parts = head.removeprefix("scalematch/").removesuffix(".py").split("/")
        if not (PACKAGE.joinpath(*parts[:-1]) / f"{parts[-1]}.py").is_file():
            return None
        return ".".join(["scalematch", *(parts if parts != ["__init__"] else [])])
    for folder in ("", "stages", "search"):
        if (PACKAGE / folder / f"{head}.py").is_file():
            return ".".join(["scalematch", *([folder] if folder else []), head])
    return None


def defining_module(name: str) -> Optional[str]:
    """The dotted name of the product module that defines class ``name`` at its top level."""
    pattern = re.compile(rf"^class {re.escape(name)}\b", re.M)
    for path in product_sources():
        if pattern.search(path.read_text()):
            return ".".join(path.relative_to(ROOT).with_suffix("").parts)
    return None


def has_attribute(obj: object, name: str) -> bool:
    """Whether ``name`` is an attribute of ``obj``, or one of its dataclass or named-tuple fields
    (a field without a default is not a class attribute)."""
    return (hasattr(obj, name) or name in getattr(obj, "__dataclass_fields__", {})
            or name in getattr(obj, "_fields", ()))


def defined_in_package(name: str) -> bool:
    """Whether the product package defines ``name``: a function, a class, or an assignment (a
    constant, a dataclass field, a class attribute)."""
    pattern = re.compile(rf"^\s*(?:def {re.escape(name)}\b|class {re.escape(name)}\b|"
                         rf"{re.escape(name)}\s*(?::[^=\n]*)?=[^=])", re.M)
    return any(pattern.search(path.read_text()) for path in product_sources())


def missing_option(token: str, known: Known) -> Optional[str]:
    option = token.split()[0]
    declared = re.search(rf'["/]{re.escape(option)}["/]', known.options)  # "--x", "--x/--no-x"
    return None if declared else f"no option {option} in cli.py, options.py"


def missing_dotted(token: str) -> Optional[str]:
    """Why the dotted name ``token`` (``module.name``, ``Class.attr``, ``x.y()``) is not found,
    or None when it is."""
    head, *rest = token.removesuffix("()").split(".")
    where = module_name(head)
    if where is not None:
        obj: object = importlib.import_module(where)
    else:
        where = defining_module(head)
        if where is None:
            return f"no product module {head}.py and no class {head} in scalematch/"
        obj = getattr(importlib.import_module(where), head)
    for i, part in enumerate(rest):
        if not has_attribute(obj, part):
            return f"{where}: {'.'.join([head, *rest[:i]])} has no {part!r}"
        obj = getattr(obj, part, None)
    return None


def missing(token: str, known: Known, modules: Sequence[ModuleType] = ()) -> Optional[str]:
    """Why ``token`` names nothing that exists, or None. ``modules``: those of its row of the
    table, where a bare name must belong to one of them."""
    word = token.strip()
    if word.startswith("--"):
        return missing_option(word, known)
    if " " in word or "*" in word:  # a line of code, a pattern of names
        return None
    if word.endswith(".py") or word.endswith("/"):
        path = word.removeprefix("scalematch/")
        return None if (PACKAGE / path).exists() else f"no file scalematch/{path}"
    name = word.removesuffix("()")
    if "." in name:
        return missing_dotted(word)
    if name == "scalematch" or name in known.presets or name in known.commands or \
            name in known.public:  # the package (and its command), a preset, a command, the API
        return None
    if modules:
        classes = [c for m in modules for c in vars(m).values()
                   if inspect.isclass(c) and c.__module__ == m.__name__]
        if any(hasattr(m, name) for m in modules) or any(has_attribute(c, name) for c in classes):
            return None
        return f"{name} is in none of {[m.__name__ for m in modules]} nor their classes"
    if module_name(name) or defined_in_package(name):
        return None
    return f"{name} is no product module, preset, command or name defined in scalematch/"


def row_problems(line: str, known: Known) -> List[str]:
    """What a row of the table of modules (``| step | module | what | parameters |``) cites
    that does not exist."""
    from scalematch.config import Config

    _, files, what, params = (c.strip() for c in line.strip().strip("|").split("|"))
    names = [module_name(t) for t in TOKEN.findall(files) if t.endswith(".py")]
    problems = [f"`{t}`: no file scalematch/{t}" for t, n in
                zip([t for t in TOKEN.findall(files) if t.endswith(".py")], names) if n is None]
    modules = [importlib.import_module(n) for n in names if n is not None]
    for token in cited_tokens(f"{files} {what}"):
        why = missing(token, known, modules)
        if why:
            problems.append(f"`{token}`: {why}")
    config = Config()
    problems += [f"`{t}`: no field of Config" for t in TOKEN.findall(params)
                 if not has_attribute(config, t)]
    return problems


def table_rows(text: str) -> List[str]:
    """The rows of DESIGN.md's table of modules (four cells, the header and rule left out)."""
    rows = [line for line in text.splitlines() if line.startswith("|") and line.count("|") == 5]
    return [r for r in rows if "---" not in r and "| module |" not in r]


def test_every_module_and_name_design_cites_exists(known):
    text = DESIGN.read_text()
    rows = table_rows(text)
    assert len(rows) > 30, "the table of modules is gone, or its shape changed"
    problems = [p for row in rows for p in row_problems(row, known)]
    prose = "\n".join(line for line in text.splitlines() if line not in rows)
    problems += [f"`{token}`: {why}" for token in cited_tokens(prose)
                 if (why := missing(token, known))]
    assert not problems, ("docs/DESIGN.md cites what the code does not have (rename it in the "
                          "doc, or the code back):\n" + "\n".join(problems))


def test_design_names_every_product_module():
    """A newcomer finds every module of the package in DESIGN.md's table by its file name."""
    cited = {t.removeprefix("scalematch/") for t in cited_tokens(DESIGN.read_text())
             if t.endswith(".py")}
    modules = [p.relative_to(PACKAGE).as_posix() for p in product_sources()]
    absent = [m for m in modules if m not in cited and m != "stages/__init__.py"]
    assert not absent, f"docs/DESIGN.md does not name these product modules: {absent}"


def test_a_renamed_or_misplaced_name_is_caught(known):
    """The check is not met by just any name: what the code lacks, or a name put in the row of
    a module that does not define it, is reported."""
    assert missing("run.run_step_renamed", known)
    assert missing("plan.search_plan_renamed", known)
    assert missing("stages/nowhere.py", known)
    assert missing("no_such_function()", known)
    assert missing("--no-such-option", known)
    assert missing("Config.no_such_field", known)
    assert row_problems("| | `search/run.py` | `run_step_renamed` | |", known)
    assert row_problems("| | `render.py` | `run_step` (it lives in search/run.py) | |", known)
    assert row_problems("| 1 | `working.py` | | `no_such_parameter` |", known)
    assert missing("run.run_step", known) is None
    assert missing("View.to_view", known) is None
    assert not row_problems("| | `search/run.py` | `run_step` | `views` |", known)


def test_every_markdown_link_resolves():
    """Every relative link of the README, the docs and scripts/README.md leads to a file."""
    broken = []
    for page in LINKED_PAGES:
        text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)  # code blocks
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if re.match(r"[a-z]+:", target) or target.startswith("#"):
                continue  # a URL, an anchor of the page itself
            if not (page.parent / target.split("#")[0]).exists():
                broken.append(f"{page.relative_to(ROOT)}: {target}")
    assert not broken, "links to missing files:\n" + "\n".join(broken)
