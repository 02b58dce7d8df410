"""The runtime: residual generator and processor interfaces, the Monitor that chains them, and
checkpoint / restore of streaming state."""

from .artifacts import load_artifact, save_artifact
from .core import Decision, Event, Monitor, MonitorResult, ResidualGenerator, ResidualProcessor
from .state import Stateful, load_state, save_state

__all__ = [
    "Decision",
    "Event",
    "Monitor",
    "MonitorResult",
    "ResidualGenerator",
    "ResidualProcessor",
    "Stateful",
    "load_artifact",
    "load_state",
    "save_artifact",
    "save_state",
]
