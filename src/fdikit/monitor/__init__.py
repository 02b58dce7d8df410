"""The runtime: residual generator and processor interfaces, the Monitor that chains them (with
its bad-data policy: plausibility, gaps, warm-up), events as episodes, and checkpoint / restore
of streaming state, and live monitoring of CSV or candump streams (:mod:`fdikit.monitor.live`)."""

from ..base.artifacts import load_artifact, save_artifact
from ..base.stage import ResidualGenerator, ResidualProcessor
from ..base.state import Stateful, load_state, save_state
from .core import STATUS_NAMES, Decision, Event, Gap, Monitor, MonitorResult
from .live import EventLog, LiveClock, LiveMonitor
from .plausibility import Plausibility, PlausibilityChecker

__all__ = [
    "STATUS_NAMES",
    "Decision",
    "Event",
    "EventLog",
    "Gap",
    "LiveClock",
    "LiveMonitor",
    "Monitor",
    "MonitorResult",
    "Plausibility",
    "PlausibilityChecker",
    "ResidualGenerator",
    "ResidualProcessor",
    "Stateful",
    "load_artifact",
    "load_state",
    "save_artifact",
    "save_state",
]
