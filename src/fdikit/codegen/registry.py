"""The registry of stage emitters outside :mod:`fdikit.codegen.stages`: emitters of new generic
stages (e.g. :mod:`.stages_mhsspt_tab`) and of the systems' stages, registered by class path
(``"module:qualname"``), so that the code generator stays below ``fdikit.systems``.

A system keeps its emitters in a ``codegen`` module of its package (``fdikit.systems.abs.codegen``
for a stage of ``fdikit.systems.abs.residuals``); :func:`emitter_for` imports it the first time it
meets one of the system's stages, and that module calls :func:`register_emitter`.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["emitter_for", "register_emitter", "registered"]

_REGISTRY: dict[str, type] = {}
_TRIED: set[str] = set()


def class_path(obj_or_cls: Any) -> str:
    """``"module:qualname"`` of an object's class (or of a class)."""
    cls = obj_or_cls if isinstance(obj_or_cls, type) else type(obj_or_cls)
    return f"{cls.__module__}:{cls.__qualname__}"


def register_emitter(path: str, emitter: type) -> None:
    """Register ``emitter`` (a :class:`~fdikit.codegen.stages.StageEmitter` subclass) for the
    stage class at ``path``.

    Parameters
    ----------
    path : str
        ``"module:qualname"`` of the stage's class, e.g.
        ``"fdikit.systems.abs.residuals:ParityR1"``; the exact class only (a subclass may change
        the step and is refused until it has its own emitter).
    emitter : type
        Called as ``emitter(stage, prefix)``.
    """
    if ":" not in path:
        raise ValueError(f"an emitter is registered by 'module:qualname', got {path!r}")
    _REGISTRY[path] = emitter


def registered() -> dict[str, type]:
    """A copy of the registry: class path -> emitter."""
    return dict(_REGISTRY)


def emitter_for(obj: Any) -> type | None:
    """The registered emitter of a stage's exact class, or None. For a stage of a system package
    (``fdikit.systems.<name>``) the package's ``codegen`` module is imported once first (it
    registers the system's emitters)."""
    path = class_path(obj)
    if path not in _REGISTRY:
        mod = type(obj).__module__.split(".")
        if mod[:2] == ["fdikit", "systems"]:
            # the system's package and its sub-packages, deepest first
            for n in range(len(mod) - 1, 2, -1):
                cand = ".".join(mod[:n]) + ".codegen"
                if cand in _TRIED:
                    continue
                _TRIED.add(cand)
                try:
                    importlib.import_module(cand)
                except ModuleNotFoundError as exc:
                    if exc.name != cand:
                        raise
                if path in _REGISTRY:
                    break
    return _REGISTRY.get(path)
