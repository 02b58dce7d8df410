"""Write the API reference pages, one per public package, from each package's ``__all__``.

Imported by ``conf.py`` at build time and by ``tests/test_docs_api.py`` (no Sphinx needed): the
reference always lists exactly what the packages export, so a new public name cannot be missed.
"""

from __future__ import annotations

import importlib
import importlib.util
from pathlib import Path

#: The public packages, in the order of the layers (top to bottom), then the systems.
PACKAGES = [
    "fdikit",
    "fdikit.signals",
    "fdikit.errors",
    "fdikit.base",
    "fdikit.io",
    "fdikit.model",
    "fdikit.faults",
    "fdikit.sim",
    "fdikit.design",
    "fdikit.residuals",
    "fdikit.detect",
    "fdikit.isolate",
    "fdikit.estimate",
    "fdikit.monitor",
    "fdikit.evaluate",
    "fdikit.report",
    "fdikit.codegen",
    "fdikit.systems",
    "fdikit.systems.abs",
    "fdikit.systems.car",
    "fdikit.systems.aircraft",
    "fdikit.systems.two_mass",
]


def public_names(package: str) -> list[str]:
    """The names ``package`` exports: its ``__all__``, or its public classes for a module without one."""
    mod = importlib.import_module(package)
    names = getattr(mod, "__all__", None)
    if names is None:
        names = [n for n, v in vars(mod).items()
                 if not n.startswith("_") and getattr(v, "__module__", None) == package]
    return list(names)


def page(package: str, owners: dict[int, str] | None = None) -> str:
    """The MyST source of the reference page of ``package``.

    ``owners`` maps ``id(obj)`` to the one package whose page indexes the object (a re-exported
    object is shown in full on every page that exports it, but is a link target only once).
    """
    mod = importlib.import_module(package)
    owners = _owners() if owners is None else owners
    names = public_names(package)
    sub = [n for n in names if _is_submodule(mod, package, n)]
    members = [n for n in names if n not in sub]
    data = [n for n in members if _kind(getattr(mod, n)) == "data"]
    code = [n for n in members if n not in data]
    lines = [f"# `{package}`", "", "```{eval-rst}", f".. automodule:: {package}", "",
             f".. currentmodule:: {package}", ""]
    if sub:
        lines += ["Subpackages: " + ", ".join(f":doc:`{package}.{n}`" for n in sub) + ".", ""]
    if code:
        lines += [".. autosummary::", "   :nosignatures:", ""] + [f"   {n}" for n in code] + [""]
    if data:
        lines += ["Data: " + ", ".join(f"``{n}``" for n in data) + ".", ""]
    for n in code:
        obj = getattr(mod, n)
        kind = _kind(obj)
        lines.append(f".. auto{kind}:: {n}")
        if kind in ("class", "exception"):
            lines += ["   :members:", "   :show-inheritance:"]
        if owners.get(id(obj), package) != package:
            lines.append("   :no-index:")
        lines.append("")
    for n in data:
        doc = attribute_doc(package, n) or ""
        body = [f"   {line}" if line else "" for line in doc.splitlines()]
        lines += [f".. py:data:: {n}", "", *body, ""]
    lines += ["```", ""]
    return "\n".join(lines)


def _kind(obj) -> str:
    import inspect

    if inspect.isclass(obj):
        return "exception" if issubclass(obj, BaseException) else "class"
    if inspect.isroutine(obj) or hasattr(obj, "py_func") or callable(obj):
        return "function"
    return "data"


def _owners() -> dict[int, str]:
    """``id(obj) -> package`` whose page indexes each exported class or function: the deepest public
    package that defines it, else the first package (in :data:`PACKAGES` order) that exports it."""
    owners: dict[int, str] = {}
    for p in PACKAGES:
        mod = importlib.import_module(p)
        for n in public_names(p):
            if _is_submodule(mod, p, n):
                continue
            obj = getattr(mod, n)
            home = getattr(obj, "__module__", None) or ""
            deepest = max((q for q in PACKAGES if home == q or home.startswith(q + ".")), key=len,
                          default=None)
            if deepest == p or (id(obj) not in owners and deepest is None):
                owners[id(obj)] = p
            elif id(obj) not in owners and deepest is not None and n not in public_names(deepest):
                owners[id(obj)] = p
    return owners


def _is_submodule(mod, package: str, name: str) -> bool:
    try:
        obj = getattr(mod, name)
    except AttributeError:
        obj = importlib.import_module(f"{package}.{name}")
    return type(obj).__name__ == "module"


def write(outdir: str | Path) -> list[Path]:
    """Write one page per package into ``outdir`` (only files whose text changed); return them."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    owners = _owners()
    for p in PACKAGES:
        path = out / f"{p}.md"
        text = page(p, owners)
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
        paths.append(path)
    return paths


def attribute_doc(package: str, name: str) -> str | None:
    """The documentation of the data attribute ``package.name``, as Sphinx reads it, or None.

    Follows ``from .x import name`` in the package's ``__init__`` to the module that assigns it,
    then takes the ``#:`` comment lines just above the assignment, an inline ``#:`` comment on
    it, or a string literal just below it (Sphinx's attribute-docstring conventions).
    """
    import ast

    spec = importlib.util.find_spec(package)
    if spec is None or spec.origin is None:
        return None
    src = Path(spec.origin).read_text()
    tree = ast.parse(src)
    lines = src.splitlines()
    for body in _bodies(tree.body):
        for i, node in enumerate(body):
            if isinstance(node, ast.ImportFrom) and any(a.asname == name or (a.asname is None and
                                                                              a.name == name)
                                                        for a in node.names):
                base = package if spec.submodule_search_locations else package.rpartition(".")[0]
                for _ in range(max(node.level - 1, 0)):
                    base = base.rpartition(".")[0]
                target = f"{base}.{node.module}" if node.level else node.module
                orig = next(a.name for a in node.names if (a.asname or a.name) == name)
                return attribute_doc(target, orig) if target else None
            targets = (node.targets if isinstance(node, ast.Assign) else
                       [node.target] if isinstance(node, ast.AnnAssign) else [])
            names = [n.id for t in targets for n in ([t] if isinstance(t, ast.Name) else
                                                      getattr(t, "elts", [])) if isinstance(n, ast.Name)]
            if name in names:
                doc = []
                k = node.lineno - 2
                while k >= 0 and lines[k].lstrip().startswith("#:"):
                    doc.insert(0, lines[k].lstrip()[2:].strip())
                    k -= 1
                if doc:
                    return "\n".join(doc)
                line = lines[node.lineno - 1]
                if "#:" in line:
                    return line.split("#:", 1)[1].strip()
                nxt = body[i + 1] if i + 1 < len(body) else None
                if (isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant)
                        and isinstance(nxt.value.value, str)):
                    return inspect_cleandoc(nxt.value.value)
                return None
    return None


def _bodies(body):
    """The module body and the bodies of its top-level ``if`` / ``try`` blocks."""
    import ast

    yield body
    for node in body:
        if isinstance(node, ast.If | ast.Try):
            yield from _bodies(node.body)
            yield from _bodies(node.orelse)
            if isinstance(node, ast.Try):
                for h in node.handlers:
                    yield from _bodies(h.body)


def inspect_cleandoc(text: str) -> str:
    import inspect

    return inspect.cleandoc(text)
