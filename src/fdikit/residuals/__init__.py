"""Residual generators: observers, parity equations, fault detection filters, sliding mode observers."""

from .observer import ObserverDesign, ObserverResidual, design_observer_residual, internal_form

__all__ = ["ObserverDesign", "ObserverResidual", "design_observer_residual", "internal_form"]
