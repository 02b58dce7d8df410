"""fdikit: model-based fault detection, isolation and reconstruction for vehicles.

``Signals`` is loaded on first use (PEP 562), so that ``import fdikit`` stays light (no NumPy):
the ``fdikit`` command installs its Ctrl-C policy before NumPy is imported.
"""

from importlib.metadata import PackageNotFoundError, version

from .errors import ConditionError, DataError, FdikitError, ModelError

try:
    #: The installed version of fdikit.
    __version__ = version("fdikit")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

__all__ = ["ConditionError", "DataError", "FdikitError", "ModelError", "Signals", "__version__"]


def __getattr__(name: str):
    if name == "Signals":
        from .signals import Signals

        globals()["Signals"] = Signals
        return Signals
    raise AttributeError(f"module 'fdikit' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
