"""fdikit: model-based fault detection, isolation and reconstruction for vehicles."""

from importlib.metadata import PackageNotFoundError, version

from .errors import ConditionError, DataError, FdikitError, ModelError
from .signals import Signals

try:
    #: The installed version of fdikit.
    __version__ = version("fdikit")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

__all__ = ["ConditionError", "DataError", "FdikitError", "ModelError", "Signals", "__version__"]
