"""What every stage shares: the residual generator and processor interfaces, streaming state
(checkpoint and restore) and design artifacts (versioned JSON manifest + NPZ, never pickle).

The rest of the core builds on these; :mod:`fdikit.monitor` re-exports them for users who compose
a monitor. The names are loaded on first use (PEP 562), so that the ``fdikit`` command can import
:mod:`fdikit.base.interrupt` (its Ctrl-C policy) before NumPy.
"""

__all__ = ["ResidualGenerator", "ResidualProcessor", "Stateful", "load_artifact", "load_state",
           "save_artifact", "save_state"]


def __getattr__(name: str):
    if name in ("load_artifact", "save_artifact"):
        from . import artifacts as mod
    elif name in ("ResidualGenerator", "ResidualProcessor"):
        from . import stage as mod
    elif name in ("Stateful", "load_state", "save_state"):
        from . import state as mod
    else:
        raise AttributeError(f"module 'fdikit.base' has no attribute {name!r}")
    value = getattr(mod, name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
