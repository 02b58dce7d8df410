"""The registry of stage emitters outside :mod:`fdikit.codegen.stages`: emitters of other core
stages (:mod:`.sensor`) and of system stages, which live with their system.

The code generator sits below ``fdikit.systems`` (the import-linter layers), so it never imports a
system. A stage class is matched to its emitter by its qualified class path
``"module:qualname"`` (the path artifacts record, :mod:`fdikit.base.artifacts`; the class's
defining module, not a re-export), in this order:

1. an emitter registered with :func:`register_emitter` (exact class: a subclass may change the
   step, so it is never matched by its base);
2. the *plugin convention*: a stage class defined in ``pkg.module`` may have its emitters in the
   sibling module ``pkg.codegen``; it is imported the first time such a stage is generated, and
   registers its emitters when imported (e.g. ``fdikit.systems.car.monitor_rav4.codegen`` for
   the RAV4 monitor's stages). Nothing is imported before a stage of that package is generated.

A user's own stage class gets its emitter the same way (call :func:`register_emitter`, or put a
``codegen`` module beside it).
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["class_path", "emitter_for", "register_emitter", "registered", "registered_emitter",
           "registered_names"]

_REGISTRY: dict[str, type] = {}
_TRIED: set[str] = set()


def class_path(obj: Any) -> str:
    """The qualified class path ``"module:qualname"`` of a stage object (its defining module).

    Examples
    --------
    >>> from fdikit.detect import Hold
    >>> class_path(Hold(["x"], 1.0))
    'fdikit.detect.threshold:Hold'
    """
    cls = obj if isinstance(obj, type) else type(obj)
    return f"{cls.__module__}:{cls.__qualname__}"


def register_emitter(path: str, emitter: type) -> None:
    """Register the C emitter of one stage class.

    Parameters
    ----------
    path : str
        The class's qualified path ``"module:qualname"`` (:func:`class_path`).
    emitter : type or callable
        A :class:`~fdikit.codegen.stages.StageEmitter` subclass, or a factory
        ``emitter(stage, prefix)`` returning one. An emitter that generates the
        stage's ``resume`` rule (the stage has a ``resume`` method: warm-up again after a gap)
        sets ``handles_resume = True`` and implements ``resume_code``; otherwise such a stage is
        refused by name.

    Raises
    ------
    DataError
        A malformed path or an emitter that is not a StageEmitter.
    """
    from ..errors import DataError

    if not isinstance(path, str) or path.count(":") != 1 or not all(path.split(":")):
        raise DataError(f"an emitter is registered under 'module:qualname', got {path!r}")
    # (a StageEmitter by its interface: the registry sits below the stages module), or a factory
    # called as emitter(stage, prefix) that returns one (e.g. by the stage's variant)
    api = ("fields", "reset_code", "step_code")
    if isinstance(emitter, type) and not all(hasattr(emitter, a) for a in api):
        raise DataError(f"the emitter of {path} must be a StageEmitter subclass, got {emitter!r}")
    if not callable(emitter):
        raise DataError(f"the emitter of {path} must be a StageEmitter subclass or a factory "
                        f"emitter(stage, prefix), got {emitter!r}")
    _REGISTRY[path] = emitter


def registered_emitter(obj: Any) -> type | None:
    """The registered emitter class of a stage object, or None (after trying the plugin
    convention: the ``codegen`` module beside the stage's defining module)."""
    key = class_path(obj)
    if key in _REGISTRY:
        return _REGISTRY[key]
    pkg = key.split(":")[0].rpartition(".")[0]
    plugin = f"{pkg}.codegen"
    # (a class of a top-level module, e.g. __main__, has no package to look in)
    if not pkg or pkg.startswith("fdikit.codegen") or plugin in _TRIED:
        return _REGISTRY.get(key)
    _TRIED.add(plugin)
    try:
        importlib.import_module(plugin)
    except ModuleNotFoundError as exc:
        if exc.name != plugin:   # the plugin exists but is broken: say so
            raise
    return _REGISTRY.get(key)


def registered_names() -> list[str]:
    """The class names of the stages with a registered emitter (those registered so far: a system's
    emitters once its ``codegen`` module was imported)."""
    return sorted({k.rsplit(":", 1)[1].rsplit(".", 1)[-1] for k in _REGISTRY})


def registered() -> dict[str, type]:
    """A copy of the registry: class path -> emitter (those registered so far)."""
    return dict(_REGISTRY)


#: The registered emitter of a stage (:func:`registered_emitter`), by its other name.
emitter_for = registered_emitter
