"""fdikit: model-based fault detection, isolation and reconstruction for vehicles.

``Signals`` and ``__version__`` are loaded on first use (PEP 562), so that ``import fdikit`` stays
light: the ``fdikit`` command installs its Ctrl-C policy before NumPy is imported.
"""

from .errors import ConditionError, DataError, FdikitError, ModelError

__all__ = ["ConditionError", "DataError", "FdikitError", "ModelError", "Signals", "__version__"]


def __getattr__(name: str):
    if name == "Signals":
        from .signals import Signals

        globals()["Signals"] = Signals
        return Signals
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            #: The installed version of fdikit.
            v = version("fdikit")
        except PackageNotFoundError:  # pragma: no cover - running from a source tree
            v = "0.0.0+unknown"
        globals()["__version__"] = v
        return v
    raise AttributeError(f"module 'fdikit' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
