"""The product does not load the lab: ``import scalematch`` and a match leave it out of memory."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

PROBE = """
import sys
import scalematch
loaded_on_import = sorted(m for m in sys.modules if m.startswith("scalematch.lab"))
from scalematch.cli import cli
from scalematch.render import write_outputs
low = scalematch.read_grey("data/demo_low.png")
high = scalematch.read_grey("data/demo_high.png")
result = scalematch.match(low, high)
assert result.matched, result.reason
loaded = sorted(m for m in sys.modules if m.startswith("scalematch.lab"))
print(loaded_on_import, loaded)
"""


def test_import_and_match_do_not_load_the_lab():
    run = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, cwd=ROOT,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "[] []"


HELP_PROBE = """
import sys
import scalematch
after_import = sorted(m for m in sys.modules if m.startswith("scalematch."))
from scalematch.cli import main
try:
    main(["--help"])
except SystemExit:
    pass
names = ("scalematch.pipeline", "scalematch.render", "scalematch.overlay", "scalematch.scalechart",
         "scalematch.captions", "scalematch.verdict", "scalematch.lab")
print(after_import, sorted(m for m in sys.modules if m.startswith(names)))
"""


def test_import_and_help_load_neither_the_pipeline_nor_the_lab():
    """``import scalematch`` loads its names on first use; the group's help lists the lab's
    commands without importing them."""
    run = subprocess.run([sys.executable, "-c", HELP_PROBE], capture_output=True, text=True,
                         cwd=ROOT, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip().endswith("[] []"), run.stdout[-300:]
    assert "lab" in run.stdout and "bench" in run.stdout  # listed all the same


# --------------------------------------------------------------------------------------------
# The shape of the product's code (the lab's studies are not held to it)
# --------------------------------------------------------------------------------------------

#: Longest function of the product package, lines from ``def`` to its last line (docstring
#: included), and most parameters (``self`` and ``cls`` not counted): a function past these
#: does several things, which one reader cannot hold at once
MAX_FUNCTION_LINES = 60
MAX_PARAMETERS = 7
#: ``match()`` reads as the method: numbered steps calling named stages
MAX_MATCH_LINES = 45


def _functions():
    import ast

    for path in sorted((ROOT / "scalematch").rglob("*.py")):
        if "lab" in path.relative_to(ROOT / "scalematch").parts:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield path.relative_to(ROOT), node


def test_no_product_function_is_longer_than_60_lines_or_takes_more_than_7_parameters():
    too_long, too_many = [], []
    for path, node in _functions():
        lines = node.end_lineno - node.lineno + 1
        names = [a.arg for a in node.args.posonlyargs + node.args.args + node.args.kwonlyargs]
        params = len([n for n in names if n not in ("self", "cls")])
        if lines > MAX_FUNCTION_LINES:
            too_long.append(f"{path}:{node.lineno} {node.name} ({lines} lines)")
        if params > MAX_PARAMETERS:
            too_many.append(f"{path}:{node.lineno} {node.name} ({params} parameters)")
    assert not too_long and not too_many, too_long + too_many


#: the longest a product module may be (the lab's measurement modules are not product)
MAX_MODULE_LINES = 700


def _product_modules():
    """(dotted name, path) of every product module: the package but its lab."""
    for path in sorted((ROOT / "scalematch").rglob("*.py")):
        rel = path.relative_to(ROOT)
        if "lab" in rel.parts[1:]:
            continue
        parts = list(rel.with_suffix("").parts)
        yield ".".join(parts[:-1] if parts[-1] == "__init__" else parts), path


def _imported(module: str, path: Path, known: set) -> set:
    """The product modules ``module`` imports anywhere in its file: at its top, under
    ``TYPE_CHECKING``, or inside a function (a circle through a late import is still one)."""
    import ast

    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                head = package[:len(package) - (node.level - 1)]
                base = ".".join(head + ([node.module] if node.module else []))
            found.update(f"{base}.{a.name}" if f"{base}.{a.name}" in known else base
                         for a in node.names)
    return {m for m in found if m in known and m not in (module, "scalematch")}


def test_no_product_module_is_longer_than_700_lines():
    long = [f"{path.relative_to(ROOT)} ({n} lines)" for _, path in _product_modules()
            if (n := len(path.read_text().splitlines())) > MAX_MODULE_LINES]
    assert not long, long


def test_no_import_circle():
    """No product module imports, however late, a module that leads back to it: the layout
    reads one way, from the command line down to the stages."""
    modules = dict(_product_modules())
    graph = {m: _imported(m, p, set(modules)) for m, p in modules.items()}
    state: dict = {}

    def circle(m: str, path: list):
        state[m] = "open"
        for n in sorted(graph[m]):
            if state.get(n) == "open":
                return path[path.index(n):] + [n] if n in path else [m, n]
            if n not in state and (found := circle(n, path + [n])):
                return found
        state[m] = "done"
        return None

    for m in sorted(graph):
        if m not in state and (found := circle(m, [m])):
            raise AssertionError(" -> ".join(found))


def test_match_reads_as_numbered_steps():
    match = next(node for path, node in _functions()
                 if path.name == "pipeline.py" and node.name == "match")
    assert match.end_lineno - match.lineno + 1 <= MAX_MATCH_LINES


def _calls(tree):
    """(call node, name of the function it is in) of every call in a module."""
    import ast

    def walk(node, owner):
        for child in ast.iter_child_nodes(node):
            inner = child.name if isinstance(child, (ast.FunctionDef,
                                                      ast.AsyncFunctionDef)) else owner
            if isinstance(child, ast.Call):
                yield child, owner
            yield from walk(child, inner)

    yield from walk(tree, "")


def test_evidence_is_built_in_the_answer_module_alone():
    """An ``Evidence`` comes from ``result.build_evidence`` alone, and only the answer module
    calls it: the decision hands on the figures its tests reached, and the answer assembles
    them once (``answer.evidence_of``)."""
    import ast

    def name(f):
        return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""

    offenders = []
    for path in sorted((ROOT / "scalematch").rglob("*.py")):
        rel = path.relative_to(ROOT / "scalematch")
        if "lab" in rel.parts:
            continue
        for call, owner in _calls(ast.parse(path.read_text())):
            made = name(call.func) == "Evidence" and owner != "build_evidence"
            built = name(call.func) == "build_evidence" and rel.as_posix() != "answer.py"
            if made or built:
                offenders.append(f"{rel}:{call.lineno} in {owner}")
    assert not offenders, offenders


def test_no_evidence_is_made_or_changed_but_by_the_answer(monkeypatch):
    """While a match runs (a match, a "no", and a fundamental matrix answered by its plane
    map), every ``Evidence`` made is one the answer module built: none comes from a
    ``replace`` or a copy elsewhere."""
    import numpy as np

    import scalematch
    from scalematch import answer, result

    made, built = [], []
    init, build = result.Evidence.__init__, answer.build_evidence

    def counted_init(self, *args, **kwargs):
        made.append(1)
        init(self, *args, **kwargs)

    def counted_build(*parts):
        built.append(1)
        return build(*parts)

    monkeypatch.setattr(result.Evidence, "__init__", counted_init)
    monkeypatch.setattr(answer, "build_evidence", counted_build)
    low = scalematch.read_grey(ROOT / "data" / "demo_low.png")
    high = scalematch.read_grey(ROOT / "data" / "demo_high.png")
    noise = np.random.default_rng(0).uniform(0, 255, high.shape).astype(np.float32)
    results = [scalematch.match(low, high), scalematch.match(low, noise),
               scalematch.match(low, high, scalematch.Config(model="fundamental"))]
    assert [r.matched for r in results] == [True, False, True]
    assert len(built) >= len(results) and len(made) == len(built)


def test_every_package_of_the_product_is_installed():
    """pyproject.toml lists the packages a wheel holds: every folder of ``scalematch/`` with an
    ``__init__.py`` (or data the code reads) is among them, so an installed copy has it all."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    folders = {".".join(p.parent.relative_to(ROOT).parts)
               for p in (ROOT / "scalematch").rglob("__init__.py")}
    assert folders <= listed, f"pyproject.toml's packages lack {sorted(folders - listed)}"
