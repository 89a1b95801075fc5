"""The path of one match through the package's modules: the modules it enters, and the calls
that climb back up to a module still waiting below (a callback, a hub re-entered).

Usage: python scripts/trace_match.py [--low LOW --high HIGH] [--no-pair LOW HIGH] [--path]
       [--write-doc docs/DESIGN.md]

Runs ``scalematch.match`` on a pair that matches (the demo pair by default) and on a pair with
no answer (the demo's coarser image against a noise image by default) under a profiler that
follows the calls of the product's own functions (``scalematch/``, the research code of
``scalematch/lab`` aside) in the thread that calls ``match``; the stages the pipeline runs on
other threads (``stages.threads``, whose calls count as its caller's) are not followed. Each function counts at its first call:
a loop over scales or views is one visit (the data's path, not its repetitions).

What it counts, for each pair:

* *modules*: the modules entered;
* *crossings*: calls from one module into another;
* *climbs back*: crossings into a module that is still on the call stack below the caller (a
  stage calling back into the pipeline that called it: a layer that reaches up), by module.

Prints the figures and, with ``--path``, the modules in the order the data first enters them
(each with the function it enters by and the module that calls it) and every climb back as
caller -> callee. ``--write-doc`` writes both pairs' figures and paths into the page's section
between ``BEGIN`` and ``END`` below (DESIGN.md, "The path of one match").
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import List, NamedTuple, Set, Tuple

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import scalematch  # noqa: E402
from scalematch.imageio import read_grey  # noqa: E402

PACKAGE = str(ROOT / "scalematch") + "/"
LAB = PACKAGE + "lab/"
#: Modules whose calls are their caller's: a map over threads calls back what it is given
TRANSPARENT = {"stages/threads.py"}
#: The markers of the section ``--write-doc`` rewrites
BEGIN = "<!-- made by scripts/trace_match.py --write-doc: begin -->"
END = "<!-- made by scripts/trace_match.py --write-doc: end -->"


def module_of(filename: str) -> str:
    """The product module of a code object's file ("stages/decision.py"), or "" outside it."""
    if not filename.startswith(PACKAGE) or filename.startswith(LAB):
        return ""
    return filename[len(PACKAGE):]


class Trace(NamedTuple):
    modules: Set[str]  #: the modules entered
    crossings: int  #: calls from one module into another (first calls)
    climbs: List[Tuple[str, str]]  #: (caller, callee) of each call into a module below
    matched: bool
    #: (module, the function it is first entered by, the calling module), in that order
    entries: List[Tuple[str, str, str]]


def trace(low: np.ndarray, high: np.ndarray) -> Trace:
    """The :class:`Trace` of ``scalematch.match(low, high)``."""
    stack: List[str] = []  # the product module of each frame ("" outside it)
    seen: Set[Tuple[str, int]] = set()
    modules: Set[str] = set()
    climbs: List[Tuple[str, str]] = []
    entries: List[Tuple[str, str, str]] = []
    crossings = 0

    def profile(frame, event, arg):  # noqa: ARG001 (the profiler's signature)
        nonlocal crossings
        if event == "return":
            if stack:
                stack.pop()
            return
        if event != "call":
            return
        code = frame.f_code
        module = module_of(code.co_filename)
        caller = next((m for m in reversed(stack) if m and m not in TRANSPARENT), "")
        stack.append(module)
        key = (code.co_filename, code.co_firstlineno)
        if not module or module in TRANSPARENT or key in seen:
            return
        seen.add(key)
        if module not in modules:
            entries.append((module, code.co_name, caller))
        modules.add(module)
        if caller and caller != module:
            crossings += 1
            below = stack[:-1]
            if module in below[:len(below) - below[::-1].index(caller) - 1]:
                climbs.append((caller, module))

    sys.setprofile(profile)
    try:
        result = scalematch.match(low, high)
    finally:
        sys.setprofile(None)
    return Trace(modules, crossings, climbs, result.matched, entries)


def report(name: str, t: Trace, path: bool) -> str:
    back = Counter(callee for _, callee in t.climbs)
    most = ", ".join(f"{m} {n}" for m, n in back.most_common())
    lines = [f"{name} ({'matched' if t.matched else 'no reliable match'}): "
             f"{len(t.modules)} modules, {t.crossings} crossings, {len(t.climbs)} climbs back"
             f"{f' ({most})' if most else ''}"]
    if path:
        lines += [f"  {k:2d}. {m} ({fn}, from {caller or 'the caller of match'})"
                  for k, (m, fn, caller) in enumerate(t.entries, 1)]
        lines += [f"  climbs back: {a} -> {b}" for a, b in t.climbs]
    return "\n".join(lines)


def write_doc(page: Path, text: str, command: str) -> None:
    """Put ``text`` (the report) between the page's markers, with the command and commit."""
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                            capture_output=True, text=True).stdout.strip() or "unknown"
    old = page.read_text()
    if BEGIN not in old or END not in old:
        raise SystemExit(f"{page}: no section marked {BEGIN} ... {END}")
    head, rest = old.split(BEGIN, 1)
    tail = rest.split(END, 1)[1]
    body = f"`{command}` (on {commit}):\n\n```text\n{text}\n```\n"
    page.write_text(f"{head}{BEGIN}\n{body}{END}{tail}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--low", default=str(ROOT / "data" / "demo_low.png"))
    ap.add_argument("--high", default=str(ROOT / "data" / "demo_high.png"))
    ap.add_argument("--no-pair", nargs=2, metavar=("LOW", "HIGH"),
                    help="a pair with no answer [default: the demo's low image against noise]")
    ap.add_argument("--path", action="store_true",
                    help="also the modules in the order entered, and every climb back")
    ap.add_argument("--write-doc", metavar="PAGE",
                    help="write the figures and paths into PAGE's marked section")
    args = ap.parse_args()
    low, high = read_grey(args.low), read_grey(args.high)
    if args.no_pair:
        no_low, no_high = (read_grey(p) for p in args.no_pair)
    else:
        import cv2

        rng = np.random.default_rng(0)
        no_low = low
        no_high = cv2.GaussianBlur(rng.uniform(0, 255, high.shape).astype(np.float32), (0, 0), 2)
    scalematch.match(low, high)  # imports and first-call work out of the trace
    text = "\n".join(report(name, trace(a, b), args.path or bool(args.write_doc))
                     for name, (a, b) in (("a match", (low, high)), ('a "no"', (no_low, no_high))))
    print(text)
    if args.write_doc:
        write_doc(Path(args.write_doc), text, "python scripts/trace_match.py --write-doc "
                  + args.write_doc)


if __name__ == "__main__":
    main()
