"""The runtime: residual generator and processor interfaces, the Monitor that chains them, and
checkpoint / restore of streaming state."""

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
    "load_state",
    "save_state",
]
