"""The runtime: residual generator and processor interfaces and the Monitor that chains them."""

from .core import Decision, Event, Monitor, MonitorResult, ResidualGenerator, ResidualProcessor

__all__ = ["Decision", "Event", "Monitor", "MonitorResult", "ResidualGenerator", "ResidualProcessor"]
