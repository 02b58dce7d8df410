"""What every stage shares: the residual generator and processor interfaces, streaming state
(checkpoint and restore) and design artifacts (versioned JSON manifest + NPZ, never pickle).

The rest of the core builds on these; :mod:`fdikit.monitor` re-exports them for users who compose
a monitor.
"""

from .artifacts import load_artifact, save_artifact
from .stage import ResidualGenerator, ResidualProcessor
from .state import Stateful, load_state, save_state

__all__ = ["ResidualGenerator", "ResidualProcessor", "Stateful", "load_artifact", "load_state",
           "save_artifact", "save_state"]
