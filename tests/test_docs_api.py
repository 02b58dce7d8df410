"""The documentation site covers the public API and its tutorials exist (no Sphinx build needed).

Every name in every public package's ``__all__`` has a docstring (a data constant: a ``#:``
comment or a string below its assignment, as Sphinx reads them) and is on its package's page of
the API reference, which ``docs/_apigen.py`` writes from ``__all__`` at build time. Every page in
the toctrees of ``docs/index.md`` exists.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"

#: Data constants documented nowhere Sphinx can read (package, name) -> file; empty, and a new
#: entry needs a reason.
UNDOCUMENTED_FOR_NOW: dict[tuple[str, str], str] = {}


def _apigen():
    if not (DOCS / "_apigen.py").exists():
        pytest.skip("docs/ is not beside the tests")
    spec = importlib.util.spec_from_file_location("_fdikit_docs_apigen", DOCS / "_apigen.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def undocumented(apigen, package: str) -> list[str]:
    """The names ``package`` exports without a docstring Sphinx can show."""
    mod = importlib.import_module(package)
    bad = []
    for name in apigen.public_names(package):
        try:
            obj = getattr(mod, name)
        except AttributeError:
            obj = importlib.import_module(f"{package}.{name}")
        if inspect.ismodule(obj) or inspect.isclass(obj) or callable(obj):
            doc = obj.__doc__
        else:
            doc = apigen.attribute_doc(package, name)
        if not (doc or "").strip() and (package, name) not in UNDOCUMENTED_FOR_NOW:
            bad.append(name)
    return bad


def missing_from_reference(apigen, package: str) -> list[str]:
    """The names ``package`` exports that its reference page does not document."""
    page = apigen.page(package)
    documented = set(re.findall(r"^\.\. (?:auto\w+|py:data)::\s+(\S+)", page, re.M))
    linked = set(re.findall(r":doc:`" + re.escape(package) + r"\.(\w+)`", page))
    return [n for n in apigen.public_names(package) if n not in documented | linked]


def test_every_public_package_is_in_the_reference():
    apigen = _apigen()
    import fdikit

    expected = {"fdikit", "fdikit.signals", "fdikit.model", "fdikit.faults", "fdikit.sim",
                "fdikit.design", "fdikit.residuals", "fdikit.detect", "fdikit.isolate",
                "fdikit.estimate", "fdikit.monitor", "fdikit.io", "fdikit.evaluate",
                "fdikit.report", "fdikit.codegen", "fdikit.base", "fdikit.systems", "fdikit.systems.abs",
                "fdikit.systems.car", "fdikit.systems.aircraft", "fdikit.systems.two_mass"}
    assert expected <= set(apigen.PACKAGES)
    index = (DOCS / "api" / "index.md").read_text()
    assert all(re.search(rf"^{re.escape(p)}$", index, re.M) for p in apigen.PACKAGES)
    assert fdikit.__name__ == "fdikit"


@pytest.mark.parametrize("package", [
    "fdikit", "fdikit.signals", "fdikit.errors", "fdikit.base", "fdikit.io", "fdikit.model",
    "fdikit.faults", "fdikit.sim", "fdikit.design", "fdikit.residuals", "fdikit.detect",
    "fdikit.isolate", "fdikit.estimate", "fdikit.monitor", "fdikit.evaluate", "fdikit.report",
    "fdikit.codegen", "fdikit.systems", "fdikit.systems.abs", "fdikit.systems.car", "fdikit.systems.aircraft",
    "fdikit.systems.two_mass"])
def test_public_names_are_documented_and_in_the_reference(package):
    apigen = _apigen()
    assert package in apigen.PACKAGES
    assert undocumented(apigen, package) == []
    assert missing_from_reference(apigen, package) == []


def test_an_undocumented_public_name_fails(monkeypatch):
    apigen = _apigen()
    mod = importlib.import_module("fdikit.evaluate")

    def no_docstring(x):
        return x

    monkeypatch.setattr(mod, "no_docstring", no_docstring, raising=False)
    monkeypatch.setattr(mod, "UNDOCUMENTED_LIMIT", 3.0, raising=False)
    monkeypatch.setattr(mod, "__all__", [*mod.__all__, "no_docstring", "UNDOCUMENTED_LIMIT"])
    assert undocumented(apigen, "fdikit.evaluate") == ["no_docstring", "UNDOCUMENTED_LIMIT"]
    # the reference is generated from __all__: the new names are on the page all the same
    assert missing_from_reference(apigen, "fdikit.evaluate") == []
    no_docstring.__doc__ = "Now documented."
    assert undocumented(apigen, "fdikit.evaluate") == ["UNDOCUMENTED_LIMIT"]


def test_attribute_docs_are_read_like_sphinx():
    apigen = _apigen()
    assert "read_log" in apigen.attribute_doc("fdikit.io", "FORMATS")          # via from .x import
    assert apigen.attribute_doc("fdikit.residuals", "NOT_SLIDING")           # a tuple assignment
    assert apigen.attribute_doc("fdikit", "__version__")                     # inside try:
    assert apigen.attribute_doc("fdikit.systems.two_mass", "DT")


def _toctree_entries() -> list[str]:
    text = (DOCS / "index.md").read_text()
    entries = []
    for block in re.findall(r"```\{toctree\}\n(.*?)```", text, re.S):
        entries += [ln.strip() for ln in block.splitlines() if ln.strip() and not ln.startswith(":")]
    return entries


def test_every_toctree_page_exists():
    if not (DOCS / "index.md").exists():
        pytest.skip("docs/ is not beside the tests")
    entries = _toctree_entries()
    tutorials = [e for e in entries if e.startswith("tutorials/")]
    assert len(tutorials) >= 8
    missing = [e for e in entries if not (DOCS / f"{e}.md").exists()]
    assert missing == []
    # and every tutorial file is listed (an orphan page would be a build warning)
    on_disk = {f"tutorials/{p.stem}" for p in (DOCS / "tutorials").glob("*.md")}
    assert on_disk == set(tutorials)


def test_tutorials_are_executable_notebooks():
    if not (DOCS / "tutorials").exists():
        pytest.skip("docs/ is not beside the tests")
    for p in sorted((DOCS / "tutorials").glob("*.md")):
        text = p.read_text()
        assert text.startswith("---\nfile_format: mystnb"), p.name
        assert "```{code-cell} ipython3" in text, p.name
