"""Model layer: linear fault models, the nonlinear model protocol, linearisation, reduction and
structural analysis."""

from .linear import GROUPS, InputGroup, LinearFaultModel
from .nonlinear import NonlinearModel, NonlinearModelProtocol

__all__ = ["GROUPS", "InputGroup", "LinearFaultModel", "NonlinearModel", "NonlinearModelProtocol"]
