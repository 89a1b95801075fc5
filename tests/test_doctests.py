"""The examples (``>>>``) in the product's docstrings run and give what they show."""

from __future__ import annotations

import doctest
import importlib
import pkgutil
import pydoc

import pytest

import scalematch

#: Every module of the product (the lab has its own tests and optional dependencies).
PRODUCT = sorted(m.name for m in pkgutil.walk_packages(scalematch.__path__, "scalematch.")
                 if not m.name.startswith("scalematch.lab")) + ["scalematch"]
#: Public functions whose docstrings must show an example.
WITH_EXAMPLES = ("scalematch", "scalematch.read_grey", "scalematch.detect", "scalematch.Config",
                 "scalematch.Config.preset", "scalematch.MatchResult.to_dict",
                 "scalematch.geometry.apply", "scalematch.geometry.compose",
                 "scalematch.geometry.similarity_parts", "scalematch.geometry.footprint",
                 "scalematch.stages.estimator.model_of")


@pytest.mark.parametrize("name", PRODUCT)
def test_docstring_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples failed in {name}"


@pytest.mark.parametrize("path", WITH_EXAMPLES)
def test_public_functions_show_an_example(path):
    obj = pydoc.locate(path)
    assert obj is not None and ">>>" in (obj.__doc__ or ""), path
