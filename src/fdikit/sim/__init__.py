"""Fixed-step simulation of many runs at once (vectorised over runs), with faults, sample-and-hold
sensors, closed-loop controllers, noise by covariance or SNR, and deterministic per-run seeds."""

from .core import METHODS, SimResult, SimulationError, sample_and_hold, simulate

__all__ = ["METHODS", "SimResult", "SimulationError", "sample_and_hold", "simulate"]
