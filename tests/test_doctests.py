"""Run the Examples sections of every fdikit module's docstrings (from the installed package)."""

import doctest
import importlib
import pkgutil

import pytest

import fdikit

MODULES = sorted(
    m.name for m in pkgutil.walk_packages(fdikit.__path__, "fdikit.")
    if not m.name.startswith("fdikit.commands")
)


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    mod = importlib.import_module(name)
    res = doctest.testmod(mod, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert res.failed == 0, f"{res.failed} docstring example(s) failed in {name}"
