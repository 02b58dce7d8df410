"""The runtime: residual generator and processor interfaces, the Monitor that chains them, and
checkpoint / restore of streaming state."""

from ..base.artifacts import load_artifact, save_artifact
from ..base.stage import ResidualGenerator, ResidualProcessor
from ..base.state import Stateful, load_state, save_state
from .core import Decision, Event, Monitor, MonitorResult

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
