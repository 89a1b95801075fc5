"""Every lab module imports (the lab's commands load them lazily, so a broken import would
otherwise show only when its command runs)."""

from __future__ import annotations

import importlib
import pkgutil

import pytest

import scalematch.lab

LAB = sorted(m.name for m in pkgutil.iter_modules(scalematch.lab.__path__, "scalematch.lab."))


@pytest.mark.parametrize("name", LAB)
def test_lab_module_imports(name):
    importlib.import_module(name)
