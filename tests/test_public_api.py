"""The public surface a user can find: what the README names can be imported from where it says.

Every dotted ``fdikit.…`` name in the README resolves, and every identifier in a "What is in the
box" bullet is exported (in ``__all__``) by one of the packages that bullet names. Each package's
``__all__`` lists only names that exist.
"""

from __future__ import annotations

import importlib
import pkgutil
import re
from pathlib import Path

import pytest

import fdikit

README = Path(__file__).resolve().parents[1] / "README.md"
#: Methods the README mentions with their object (``run(signals)``, ``to_pandas()``), not exports.
METHODS = {"run", "reset", "step", "to_pandas", "from_pandas"}


def _resolve(dotted: str):
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ModuleNotFoundError:
            continue
        for p in parts[i:]:
            obj = getattr(obj, p)
        return obj
    raise ImportError(dotted)


def _readme() -> str:
    if not README.exists():
        pytest.skip("README.md is not beside the tests")
    return README.read_text()


def test_readme_dotted_names_resolve():
    names = sorted(set(re.findall(r"`(fdikit(?:\.\w+)+)", _readme())))
    assert len(names) >= 15
    bad = []
    for n in names:
        try:
            _resolve(n)
        except (ImportError, AttributeError) as exc:
            bad.append(f"{n}: {exc}")
    assert not bad, bad


def test_readme_box_identifiers_are_exported_where_the_readme_says():
    text = _readme()
    box = text.split("## What is in the box")[1].split("\n## ")[0]
    bullets = re.split(r"\n- ", box)
    checked, bad = 0, []
    for b in bullets:
        pkgs = re.findall(r"\(`(fdikit\.\w+)`(?:, `(fdikit\.\w+)`)?\)", b)
        mods = [importlib.import_module(p) for pair in pkgs for p in pair if p]
        if not mods:
            continue
        for tok in re.findall(r"`([A-Za-z_]\w*)(?:\([^`]*\))?`", b):
            if tok.startswith("fdikit") or tok in METHODS or (tok.islower() and len(tok) <= 2):
                continue
            if any(tok in getattr(m, "__all__", ()) for m in mods):
                checked += 1
            elif not any(hasattr(m, tok) for m in mods):
                bad.append(f"{tok} (bullet on {[m.__name__ for m in mods]})")
            else:
                bad.append(f"{tok} exists but is not in __all__ of {[m.__name__ for m in mods]}")
    assert checked > 30
    assert not bad, bad


@pytest.mark.parametrize("name", sorted(m.name for m in pkgutil.walk_packages(fdikit.__path__, "fdikit.")
                                        if m.ispkg))
def test_package_all_is_its_api(name):
    mod = importlib.import_module(name)
    assert hasattr(mod, "__all__"), f"{name} has no __all__"
    missing = [n for n in mod.__all__ if not hasattr(mod, n)
               and importlib.util.find_spec(f"{name}.{n}") is None]
    assert not missing, f"{name}.__all__ names what it does not have: {missing}"


def test_readme_promise_reconstruction_from_residuals():
    # issue 14: "from fdikit.residuals import design_reconstructor" raised ImportError
    from fdikit.residuals import design_reconstructor

    assert callable(design_reconstructor)
