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
names = ("scalematch.pipeline", "scalematch.render", "scalematch.lab")
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
